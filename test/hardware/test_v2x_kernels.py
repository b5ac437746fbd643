"""The compiled decoder loops against plain-Python statements of the same rules."""

import numpy as np
import pytest

from maglev_ros.hardware.packet import PWM_FULL_SCALE
from maglev_ros.hardware.v2x_kernels import first_bad_record, unwrap_run
from maglev_ros.hardware.v2x_stream import pack_records, record_size

MAX_FIELD = 1000.0
FIELD_BITS = int(np.float32(MAX_FIELD).view(np.uint32))
MASK = (1 << 32) - 1


def rows_of(stamps, field, pwm) -> np.ndarray:
    n_sensors = np.asarray(field).shape[1]
    data = pack_records(stamps, field, pwm)
    return np.frombuffer(data, '<u4').reshape(len(stamps), record_size(n_sensors) // 4)


def reference_first_bad(stamps, field, pwm, start, prev_ts, lo=100, hi=10_000) -> int:
    """The invariants of the module docstring of v2x_stream, record by record."""
    for i in range(start, len(stamps)):
        prev = prev_ts if i == 0 else stamps[i - 1]
        if not lo <= (stamps[i] - prev) & MASK <= hi:
            return i
        if not np.all(np.abs(field[i]) <= MAX_FIELD):  # NaN fails too
            return i
        if not np.all((pwm[i] >= -PWM_FULL_SCALE) & (pwm[i] <= PWM_FULL_SCALE)):
            return i
    return len(stamps)


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_first_bad_record_matches_the_rules(n_sensors):
    rng = np.random.default_rng(n_sensors)
    n = 12
    damage = [
        None,
        lambda s, f, p, i: s.__setitem__(i, (s[i - 1] if i else 0) + 50),  # step too small
        lambda s, f, p, i: s.__setitem__(slice(i, None), s[i:] + 20_000),  # step too large
        lambda s, f, p, i: f.__setitem__((i, n_sensors - 1, 2), np.nan),
        lambda s, f, p, i: f.__setitem__((i, 0, 1), -np.inf),
        lambda s, f, p, i: f.__setitem__((i, 0, 0), 1000.0001),
        lambda s, f, p, i: p.__setitem__((i, 3), PWM_FULL_SCALE + 1),
        lambda s, f, p, i: p.__setitem__((i, 0), -PWM_FULL_SCALE - 1),
    ]
    for trial in range(200):
        stamps = ((1 << 32) - 1000 + 200 * np.arange(n)) & MASK  # wraps inside the block
        field = rng.uniform(-MAX_FIELD, MAX_FIELD, (n, n_sensors, 3)).astype(np.float32)
        field[0, 0, 0] = -MAX_FIELD  # the bound itself is plausible
        pwm = rng.integers(-PWM_FULL_SCALE, PWM_FULL_SCALE + 1, (n, 4))
        pwm[1, 2] = PWM_FULL_SCALE
        hurt = damage[trial % len(damage)]
        if hurt is not None:
            hurt(stamps, field, pwm, int(rng.integers(0, n)))
        start = int(trial % 2)
        prev_ts = (int(stamps[0]) - 200) & MASK
        rows = rows_of(stamps, field, pwm)
        expected = reference_first_bad(stamps, field.astype(np.float64), pwm, start, prev_ts)
        got = first_bad_record(
            rows, start, prev_ts, 3 * n_sensors, 100, 10_000, FIELD_BITS, PWM_FULL_SCALE
        )
        assert got == expected, trial


def test_unwrap_run_continues_across_wraps_and_restarts():
    ts = ((np.arange(6, dtype=np.int64) * 200 + (1 << 32) - 500) & MASK).astype(np.uint32)
    first, restarts, wraps = unwrap_run(ts, -1, 0, 200)  # the stream's first run
    np.testing.assert_array_equal(first, int(ts[0]) + 200 * np.arange(6))
    assert (restarts, wraps) == (0, 1)
    # the next run continues the time, across the next wrap of the raw clock
    nxt = (int(ts[-1]) + 200 * np.arange(1, 4)).astype(np.uint32)
    times, restarts, wraps = unwrap_run(nxt, int(ts[-1]), int(first[-1]), 200)
    np.testing.assert_array_equal(times, first[-1] + 200 * np.arange(1, 4))
    assert (restarts, wraps) == (0, 0)
    # the board restarted: its clock is back near zero; time goes on one period later
    again = np.array([1000, 1200], np.uint32)
    times, restarts, wraps = unwrap_run(again, int(nxt[-1]), int(times[-1]), 200)
    np.testing.assert_array_equal(times, [2**32 + 1300, 2**32 + 1500])
    assert (restarts, wraps) == (1, 0)


def test_one_compiled_signature_whatever_the_stream():
    # a new signature compiles in the middle of a stream (up to a second, holding the
    # GIL); the decoder passes one array type whatever the runs look like
    from maglev_ros.hardware.v2x_stream import RecordDecoder

    rng = np.random.default_rng(0)
    n = 400
    data = pack_records(
        200 * np.arange(n), rng.normal(0.0, 10.0, (n, 1, 3)), rng.integers(-100, 100, (n, 4))
    )
    size = record_size(1)
    decoder = RecordDecoder(1)
    for start in range(0, 100 * size, 5 * size):  # bursts
        decoder.feed(data[start : start + 5 * size])
    decoder.feed(b'\xff' * 37)  # garbage, then single records and odd chunks
    for start in range(100 * size, 200 * size, size):
        decoder.feed(data[start : start + size])
    decoder.feed(data[200 * size + 3 : 300 * size])
    decoder.flush()
    assert len(first_bad_record.signatures) == 1
    assert len(unwrap_run.signatures) == 1
