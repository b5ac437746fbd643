"""The excitation the controller adds to its command (``maglev_ros.control.excitation``)."""

import numpy as np
import pytest

from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.control.excitation import (
    CommandExcitation,
    ExcitationSchedule,
    LoopExcitationError,
)

RATE = 5000.0


def test_schedule_is_the_seeded_signal_on_the_pattern_from_its_start():
    cfg = CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs', seed=3, length=1000, start=0.01)
    schedule = ExcitationSchedule(cfg, RATE)
    assert schedule.start_index == 50
    seq = schedule.sequence(2100)
    assert np.all(seq[:50] == 0.0)
    # pairs: x+ = r_x, x- = -r_x, y+ = r_y, y- = -r_y, levels +-0.1 A
    np.testing.assert_array_equal(seq[50:, 1], -seq[50:, 0])
    np.testing.assert_array_equal(seq[50:, 3], -seq[50:, 2])
    assert set(np.unique(np.abs(seq[50:]))) == {0.1}
    assert np.corrcoef(seq[50:1050, 0], seq[50:1050, 2])[0, 1] < 0.2  # independent x and y
    # periodic with `length` samples, cycles 0: forever
    np.testing.assert_array_equal(seq[1050:2050], seq[50:1050])
    # deterministic: the same settings give the same numbers (node and ROS-free loop)
    np.testing.assert_array_equal(ExcitationSchedule(cfg, RATE).sequence(2100), seq)
    # a PRBS of the excitation package, band (0, 0.2): a level lasts 5 samples
    x_pair = CommandExcitation('prbs', 0.1, (0.0, 0.2), 'x_pair', seed=3, length=1000)
    column = ExcitationSchedule(x_pair, RATE).sequence(1000)[:, 0]
    assert np.all(column.reshape(-1, 5) == column.reshape(-1, 5)[:, :1])


def test_cycles_end_the_excitation_and_none_adds_nothing():
    cfg = CommandExcitation('multisine', 0.05, (0.01, 0.1), 'x_pair', length=200, cycles=2)
    seq = ExcitationSchedule(cfg, RATE).sequence(500)
    assert np.abs(seq[:400]).max() == pytest.approx(0.05)
    assert np.all(seq[400:] == 0.0)
    off = ExcitationSchedule(CommandExcitation(), RATE)
    assert not off.enabled and np.all(off.sequence(10) == 0.0)


@pytest.mark.parametrize(
    'settings, match',
    [
        ({'signal': 'noise'}, "signal must be one of none, prbs, .*, got 'noise'"),
        ({'amplitude': -0.1}, 'amplitude must be >= 0 A, got -0.1'),
        ({'band': (0.3, 0.2)}, 'band must be (low, high)'),
        ({'pattern': 'diagonal'}, "pattern must be one of pairs"),
        ({'length': 0}, 'length must be an integer >= 1, got 0'),
        ({'start': -1.0}, 'start must be >= 0 s, got -1.0'),
    ],
)  # fmt: skip
def test_bad_settings_name_the_value(settings, match):
    with pytest.raises(LoopExcitationError, match=match.replace('(', r'\(').replace(')', r'\)')):
        CommandExcitation(**settings)


def test_a_prbs_band_must_start_at_zero():
    cfg = CommandExcitation('prbs', band=(0.1, 0.2))
    with pytest.raises(LoopExcitationError, match='signal prbs: band of a prbs must start at 0'):
        ExcitationSchedule(cfg, RATE)


def test_the_levitating_magnet_stays_within_half_a_millimetre_under_the_excitation():
    """The lab's excitation (PRBS 0.1 A on both pairs, band (0, 0.2)) in the simulated loop.

    KF + LQR, V2, 0.1 mT noise, 0.098 mT steps, sensor delay, coil dynamics, the
    command one sample late: 1 s of excitation after 0.1 s of hold.
    """
    loop = make_closed_loop('maggy_v2', seed=2)
    cfg = CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs', seed=1, start=0.1)
    n = int(1.1 * RATE)
    excitation = ExcitationSchedule(cfg, RATE).sequence(n)
    result = loop.run(1.1, excitation=excitation)
    assert not result.crashed, result.reason
    excited = result.t >= 0.1
    excursion = np.abs(result.position_error()[excited]).max(axis=0)
    assert np.all(excursion < 0.5e-3), excursion
    total = result.command + excitation[: len(result.t)]
    assert np.abs(total).max() <= 1.1 + 1e-12  # the LQR's 1 A and 0.1 A on top
