"""The time base on the first output's own stamps: shared stamps are matched exactly.

A board driver stamps the field and the currents of one record alike; its
stamps are uniform sample to sample but drift (clock rate) and slew (offset
corrections) against any fixed grid. Lockstep bags (stamps exactly on a grid)
are covered in ``test_datasets.py``.
"""

import numpy as np
import pytest

from maglev_ros.bags import BagError
from maglev_ros.bags.alignment import Source, align
from maglev_ros.hardware.board_clock import BoardClock

T0_NS = 1_700_000_000_000_000_000


def record(stamps, seed=0):
    """An output (3 fields) and an input (4 currents) sharing ``stamps``."""
    rng = np.random.default_rng(seed)
    y = rng.standard_normal((stamps.size, 3)) * 1e-3
    u = rng.integers(-4096, 4096, (stamps.size, 4)) / 1000.0
    return (
        Source('/maglev/sensor_0/field', stamps, y, 'output'),
        Source('/maglev/currents', stamps, u, 'input'),
    )


def slewed_stamps(n, seed=0):
    """Board samples every 200 us, 50 ppm drift, the offset slewed at 2 % by +-0.8 ms.

    Every 2000 samples the offset starts moving by up to 0.8 ms (either way) at 4 us
    per sample, as ``BoardClock`` does after a new latency minimum.
    """
    rng = np.random.default_rng(seed)
    step = np.zeros(n)
    for start in range(1000, n, 2000):
        target = rng.uniform(-800_000, 800_000)
        ramp = np.minimum(np.arange(n - start) * 4000.0, abs(target)) * np.sign(target)
        step[start:] += ramp
    return T0_NS + np.rint(np.arange(n) * 200_000 * (1 + 50e-6) + step).astype(np.int64)


@pytest.mark.parametrize('Ts', [None, 200e-6])
def test_drifting_uniform_stamps_shared_by_output_and_input_are_exact(Ts):
    # 200.01 us per sample: after 100 000 samples 1 ms (5 samples) off a 200 us grid
    stamps = T0_NS + np.rint(np.arange(100_000) * 200_010.0).astype(np.int64)
    y, u = record(stamps)
    al = align([y, u], Ts=Ts)
    assert al.base == 'stamps'
    assert [r.method for r in al.reports] == ['exact', 'exact']
    assert al.N == 100_000 and al.trimmed == (0, 0) and al.gaps == ()
    assert al.t0_ns == stamps[0]
    assert al.Ts == (pytest.approx(200.01e-6, rel=1e-9) if Ts is None else Ts)
    np.testing.assert_array_equal(al.values[0], y.values)
    np.testing.assert_array_equal(al.values[1], u.values)


def test_a_slewing_offset_is_exact_where_a_fixed_grid_is_not():
    stamps = slewed_stamps(60_000)
    Ts = np.median(np.diff(stamps)) * 1e-9
    grid = stamps[0] + np.rint(np.arange(stamps.size) * Ts * 1e9)
    assert np.abs(stamps - grid).max() > 0.5 * 200_000  # far off any fixed grid
    y, u = record(stamps, seed=1)
    al = align([y, u])
    assert al.base == 'stamps'
    assert [r.method for r in al.reports] == ['exact', 'exact']
    np.testing.assert_array_equal(al.values[0], y.values)
    np.testing.assert_array_equal(al.values[1], u.values)


def test_board_clock_stamps_are_exact():
    # the driver's path: records read in bursts with random latency, mapped by BoardClock,
    # the same stamps on the field and the currents of each record
    rng = np.random.default_rng(4)
    clock, board_us, stamps = BoardClock(), 1_000_000, []
    while board_us < 21_000_000:
        times = board_us + 200 * np.arange(int(rng.integers(1, 40)))
        board_us = int(times[-1]) + 200
        latency_us = 20 + rng.exponential(300) + (600 if (board_us // 1_000_000) % 4 == 3 else 0)
        clock.observe(
            int(times[-1]),
            T0_NS + round(int(times[-1]) * 1000 * (1 + 30e-6)) + int(latency_us * 1000),
        )
        stamps.append(clock.to_host(times))
    stamps = np.concatenate(stamps)
    y, u = record(stamps, seed=2)
    al = align([y, u], Ts=200e-6)
    assert [r.method for r in al.reports] == ['exact', 'exact'] and al.gaps == ()
    np.testing.assert_array_equal(al.values[0], y.values)
    np.testing.assert_array_equal(al.values[1], u.values)


def test_an_input_on_its_own_clock_is_still_held():
    stamps = slewed_stamps(20_000, seed=3)
    y, _ = record(stamps)
    # commands by log time, 1 kHz on the host clock: not the board's stamps
    log = T0_NS + 130_000 + np.arange(4_000, dtype=np.int64) * 1_000_000
    commands = np.arange(4_000.0)[:, None]
    al = align([y, Source('/maglev/currents/command', log, commands, 'input', 'log')])
    assert al.base == 'stamps'
    assert [r.method for r in al.reports] == ['exact', 'zoh']
    # the last command stamped at or before each sample (tolerance 10 us)
    base = stamps[al.trimmed[0] : stamps.size - al.trimmed[1]]
    held = np.searchsorted(log, base + 10_000, side='right') - 1
    assert held.min() == 0
    np.testing.assert_array_equal(al.values[1][:, 0], commands[held, 0])
    np.testing.assert_array_equal(al.values[0], y.values[al.trimmed[0] :][: al.N])


def test_an_output_on_its_own_clock_is_interpolated_at_the_base_stamps():
    stamps = slewed_stamps(20_000, seed=5)
    y, _ = record(stamps)
    other_t = T0_NS + 70_000 + np.arange(20_000, dtype=np.int64) * 200_000  # half-way off
    other = Source('/other', other_t, np.sin((other_t - T0_NS) * 1e-8)[:, None], 'output')
    al = align([y, other])
    assert [r.method for r in al.reports] == ['exact', 'linear']
    base = stamps[al.trimmed[0] : stamps.size - al.trimmed[1]]
    np.testing.assert_allclose(al.values[1][:, 0], np.sin((base - T0_NS) * 1e-8), atol=1e-4)


def test_shared_stamps_one_to_one():
    # an extra message 1 us after a sample: two messages for one base sample
    stamps = slewed_stamps(5_000, seed=6)
    y, u = record(stamps)
    extra = np.sort(np.append(stamps, stamps[2_000] + 1_000))
    values = np.insert(np.asarray(y.values), 2_001, 9.0, axis=0)
    al = align([y, Source('/y2', extra, values, 'output')])
    assert [r.method for r in al.reports] == ['exact', 'linear']


def test_a_base_off_its_period_uses_the_grid():
    stamps = slewed_stamps(5_000, seed=7)
    # a step of 30 us (15 % of Ts, the old clock's jump) or an explicit other Ts: the grid
    stepped = stamps.copy()
    stepped[2_500:] += 30_000
    y, u = record(stepped)
    al = align([y, u])
    assert al.base == 'grid' and al.reports[0].method == 'linear'
    al = align(list(record(stamps)), Ts=250e-6)  # resampling to another rate
    assert al.base == 'grid' and [r.method for r in al.reports] == ['linear', 'zoh']
    # a gap in the base: the grid, and the gap is refused as before
    y, u = record(np.delete(stamps, [100, 101]))
    with pytest.raises(BagError, match="gap in topic '/maglev/sensor_0/field': 2 missing"):
        align([y, u])
    al = align([y, u], allow_gaps=True)
    assert al.base == 'grid' and [r.method for r in al.reports] == ['linear', 'zoh']


def test_an_input_cut_one_sample_short_is_exact_and_trims_the_end():
    # the recorder closed between a record's field and its currents message
    stamps = slewed_stamps(3_000, seed=8)
    y, u = record(stamps)
    cut = Source(u.topic, stamps[:-1], np.asarray(u.values)[:-1], 'input')
    al = align([y, cut])
    assert [r.method for r in al.reports] == ['exact', 'exact']
    assert al.trimmed == (0, 1) and al.N == 2_999  # the last field has no currents
    np.testing.assert_array_equal(al.values[0], np.asarray(y.values)[:-1])
    np.testing.assert_array_equal(al.values[1], np.asarray(u.values)[:-1])
