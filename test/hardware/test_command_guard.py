"""The command guard: validate, clamp, enable, time out and scale, without ROS."""

import numpy as np
import pytest

from maglev_ros.hardware.command_guard import CommandGuard
from maglev_ros.hardware.scaling import CurrentScaling

MS = 1_000_000  # ns


def guard(**kwargs):
    kwargs.setdefault('enabled', True)
    return CommandGuard(CurrentScaling(1000.0), 2.0, 0.1, **kwargs)


def test_valid_commands_become_pwm_counts():
    g = guard()
    decision = g.command([0.5, -0.25, 1.5, -1.999], now_ns=0)
    assert decision.warning == ''
    np.testing.assert_array_equal(decision.counts, [500, -250, 1500, -1999])
    assert decision.counts.dtype == np.int64


@pytest.mark.parametrize(
    'values, warning',
    [
        ([np.nan, 0.0, 0.0, 0.0], 'rejected command: currents must be finite, got [nan, '),
        ([0.0, np.inf, 0.0, 0.0], 'rejected command: currents must be finite'),
        ([0.0, 0.0, -np.inf, 0.0], 'rejected command: currents must be finite'),
        ([0.2, 0.2, 0.2], 'rejected command: need 4 currents (x+, x-, y+, y-), got 3'),
        ([0.2] * 5, 'rejected command: need 4 currents (x+, x-, y+, y-), got 5'),
    ],
)
def test_bad_commands_send_nothing_and_keep_the_timeout_running(values, warning):
    g = guard()
    g.command([0.1] * 4, now_ns=0)
    decision = g.command(values, now_ns=90 * MS)
    assert decision.counts is None and decision.warning.startswith(warning)
    assert g.counters['commands_rejected'] == 1
    assert g.check_timeout(now_ns=101 * MS) == pytest.approx(0.101)  # from the valid one


def test_beyond_the_limit_is_clamped_and_counted():
    g = guard()
    decision = g.command([100.0, -5.0, 1.0, 0.0], now_ns=0)
    np.testing.assert_array_equal(decision.counts, [2000, -2000, 1000, 0])
    assert decision.warning == 'clamped command [100.0, -5.0, 1.0, 0.0] A to +-2.000 A'
    assert g.counters['commands_clamped'] == 1
    g.configure(current_limit=1.5, command_timeout=0.1)  # a run-time parameter change
    np.testing.assert_array_equal(g.command([3.0] * 4, now_ns=0).counts, [1500] * 4)


def test_disabled_means_zero_counts():
    g = guard(enabled=False)
    assert not g.enabled
    decision = g.command([1.0] * 4, now_ns=0)
    np.testing.assert_array_equal(decision.counts, [0, 0, 0, 0])  # sent, as zeros
    assert g.set_enabled(True) is None
    np.testing.assert_array_equal(g.command([1.0] * 4, now_ns=0).counts, [1000] * 4)
    np.testing.assert_array_equal(g.set_enabled(False), [0, 0, 0, 0])  # zero at once


def test_timeout_fires_once_until_the_next_valid_command():
    g = guard()
    assert g.check_timeout(now_ns=10**12) is None  # no command yet: nothing to time out
    g.command([0.7] * 4, now_ns=0)
    assert g.check_timeout(now_ns=100 * MS) is None  # not past 0.1 s
    assert g.check_timeout(now_ns=150 * MS) == pytest.approx(0.15)
    assert g.timed_out and g.counters['timeouts'] == 1
    assert g.check_timeout(now_ns=300 * MS) is None  # zeros sent once
    g.command([0.7] * 4, now_ns=400 * MS)
    assert not g.timed_out
    assert g.check_timeout(now_ns=501 * MS) == pytest.approx(0.101)
    assert g.counters['timeouts'] == 2


def test_read_only_board_ignores_commands():
    g = guard(read_only=True)
    decision = g.command([1.0] * 4, now_ns=0)
    assert decision.counts is None and 'read-only' in decision.warning
    assert g.counters['commands_ignored'] == 1 and g.counters['commands_rejected'] == 0


@pytest.mark.parametrize(
    'limit, timeout, name', [(0.0, 0.1, 'current_limit'), (1.0, np.nan, 'command_timeout')]
)
def test_invalid_settings_name_the_value(limit, timeout, name):
    with pytest.raises(ValueError, match=f'{name} must be a positive finite number'):
        CommandGuard(CurrentScaling(1000.0), limit, timeout)


def test_limit_above_full_scale_is_refused():
    scaling = CurrentScaling(1000.0)  # full scale 4.096 A
    with pytest.raises(
        ValueError, match=r'current_limit 5 A is above the board\'s full scale 4.096 A'
    ):
        CommandGuard(scaling, 5.0, 0.1)
    guard = CommandGuard(scaling, 4.096, 0.1)  # exactly the full scale is fine
    with pytest.raises(ValueError, match='current_limit 4.2 A is above'):
        guard.configure(4.2, 0.1)
    assert guard.current_limit == 4.096


def test_pairs_guard_sends_the_antisymmetric_part():
    from maglev_ros.hardware.command_guard import pair_differences
    from maglev_ros.hardware.scaling import V4X_PWM_FULL_SCALE

    scaling = CurrentScaling.from_supply(12.0, 4.0, full_scale=V4X_PWM_FULL_SCALE)  # 85 /A
    guard = CommandGuard(scaling, 2.0, 0.1, enabled=True, pairs=True)
    decision = guard.command([1.0, -1.0, -0.5, 0.5], 0)
    assert decision.counts.tolist() == [85, -85, -42, 42]  # -42.5 rounds half to even
    assert pair_differences(decision.counts) == (85, -42)
    assert guard.common_mode_dropped == 0
    decision = guard.command([1.0, 0.0, 0.0, 0.0], 1)  # half of it is common mode
    assert decision.counts.tolist() == [42, -42, 0, 0]
    assert guard.common_mode_dropped == 1
    decision = guard.command([3.0, -3.0, 0.0, 0.0], 2)  # clamped to the 2 A limit
    assert decision.counts.tolist() == [170, -170, 0, 0]
    assert guard.counters['commands_clamped'] == 1
    with pytest.raises(ValueError, match='must be'):
        pair_differences([1, 2, 0, 0])
