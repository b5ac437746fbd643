"""The controller stage: inputs paired by stamp, excitation, delay, silence and readiness."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_ros.control import ControllerConfig, make_controller
from maglev_ros.control.excitation import CommandExcitation
from maglev_ros.loop.commander import Commander, check_trigger
from maglev_ros.physics import make_model
from maglev_ros.physics.equilibria import find_equilibria

MODEL = make_model('maggy_v2')
X_EQ = MODEL.hover_state(find_equilibria(MODEL)[0].z)
RATE = 1000.0
PERIOD_NS = 1_000_000


def _commander(**kw) -> Commander:
    config = ControllerConfig(sample_rate=RATE, input_timeout=0.02, **kw.pop('config', {}))
    return Commander(make_controller(MODEL, config), MODEL.n_outputs // 3, **kw)


def _state(dx: float) -> np.ndarray:
    x = X_EQ.copy()
    x[0] += dx
    return x


def test_each_sample_is_answered_once_in_stamp_order_whatever_order_its_parts_came_in():
    stage, reference = _commander(), _commander()
    currents = np.zeros(4)
    out = []
    out += stage.sample_part(1, PERIOD_NS, _state(1e-4))  # the estimate first
    out += stage.sample_part(0, PERIOD_NS, currents)
    out += stage.sample_part(0, 2 * PERIOD_NS, currents)  # currents first
    out += stage.sample_part(1, 2 * PERIOD_NS, _state(2e-4))
    assert [c.stamp_ns for c in out] == [PERIOD_NS, 2 * PERIOD_NS]
    want = [reference.controller.command(k * 1e-3, _state(k * 1e-4), currents) for k in (1, 2)]
    for got, w in zip(out, want, strict=True):
        assert np.array_equal(got.total, w) and got.excitation is None
    assert np.any(out[1].total != 0)  # off the equilibrium: the LQR pushes back
    assert stage.commands == 2


def test_delay_commands_publishes_for_sample_k_the_command_of_k_minus_1():
    stage, plain = _commander(delay_commands=True), _commander()
    totals, wanted = [], []
    for k in range(1, 4):
        for s, out in ((stage, totals), (plain, wanted)):
            s.sample_part(0, k * PERIOD_NS, np.zeros(4))
            out += [c.total for c in s.sample_part(1, k * PERIOD_NS, _state(k * 1e-4))]
    assert np.array_equal(totals[0], np.zeros(4))
    assert all(np.array_equal(a, b) for a, b in zip(totals[1:], wanted[:-1], strict=True))
    stage.enable(False)  # the command held back is dropped with the disable
    stage.sample_part(0, 4 * PERIOD_NS, np.zeros(4))
    (last,) = stage.sample_part(1, 4 * PERIOD_NS, _state(4e-4))
    assert np.array_equal(last.total, np.zeros(4))


def test_the_excitation_of_each_sample_is_added_and_reported_apart():
    excitation = CommandExcitation(signal='prbs', amplitude=0.1, seed=3)
    stage = _commander(excitation=excitation)
    plain = _commander()
    first = 5 * PERIOD_NS  # the excitation's sample 0 is the first stamp seen
    for k in range(4):
        stamp = first + k * PERIOD_NS
        stage.sample_part(0, stamp, np.zeros(4))
        (c,) = stage.sample_part(1, stamp, X_EQ)
        plain.sample_part(0, stamp, np.zeros(4))
        (p,) = plain.sample_part(1, stamp, X_EQ)
        assert np.array_equal(c.excitation, stage.schedule.value(k))
        assert np.allclose(c.total, p.total + c.excitation)
    assert np.any(c.excitation != 0)
    assert 'prbs' in stage.diagnostic_values()['excitation']


def test_estimate_trigger_is_ready_once_heard_and_zeroes_once_per_silence():
    stage = _commander(trigger='estimate')
    assert stage.check_stale(0.0, estimator_heard=False) is None
    assert stage.check_stale(0.1, estimator_heard=True) is None  # heard from 0.1 s on
    assert stage.check_stale(0.5, estimator_heard=True) is None  # 0.4 s < ready_after
    ready = stage.check_stale(0.7, estimator_heard=True)
    assert ready is not None and np.array_equal(ready.total, np.zeros(4))
    answer = stage.estimate(PERIOD_NS, _state(2e-4), now_s=1.0)
    assert np.any(answer.total != 0)
    assert stage.check_stale(1.01, estimator_heard=True) is None  # within input_timeout
    silence = stage.check_stale(1.05, estimator_heard=True)
    assert silence is not None and np.array_equal(silence.total, np.zeros(4))
    assert stage.check_stale(1.2, estimator_heard=True) is None  # once per silence


def test_a_stopped_graph_is_an_error_whatever_the_controller_says():
    stage = _commander()
    stage.heard(0)
    level, message, _ = stage.diagnostic(10_000_000, period=0.5)
    assert level < 2 and not message.startswith('no sample')  # waiting, not stopped
    level, message, values = stage.diagnostic(2_000_000_000, period=0.5)
    assert level == 2 and message.startswith('no sample for 2.00 s: no commands sent')
    assert values['commands'] == 0


def test_references_and_triggers_are_checked():
    stage = _commander()
    assert stage.set_reference('elsewhere', (0, 0, 0.03))[0] is False
    ok, text = stage.set_reference('', (1e-4, 0.0, X_EQ[2]))
    assert ok and text.startswith('reference 0.0001 0')
    pd = _commander(config={'mode': 'pd'})
    assert pd.set_reference('', (0, 0, 0.03)) == (
        False,
        'maglev/reference ignored: the PD holds the equilibrium',
    )
    with pytest.raises(ValueError, match="trigger 'estimate' needs mode 'lqr'"):
        check_trigger('estimate', 'pd')
    with pytest.raises(ValueError, match='trigger must be one of sample, estimate'):
        check_trigger('each', 'lqr')


@pytest.mark.parametrize('enabled', [True, False])
def test_the_warm_up_loads_the_law_and_leaves_no_trace(enabled):
    config = ControllerConfig(sample_rate=RATE, command_delay=3)
    fresh, warmed = make_controller(MODEL, config), make_controller(MODEL, config)
    fresh.set_enabled(enabled)
    warmed.set_enabled(enabled)
    stage = Commander(warmed, MODEL.n_outputs // 3, trigger='estimate')
    assert warmed.enabled == enabled and not warmed.active
    for k in range(1, 6):  # the pending commands and the watchdog start as a fresh one's
        got = stage.estimate(k * PERIOD_NS, _state(k * 1e-4), 0.0)
        want = fresh.command(k * 1e-3, _state(k * 1e-4))
        np.testing.assert_array_equal(got.total, want)
