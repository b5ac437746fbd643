"""LQR design, steady state, limits, watchdog, enable, PD signs, YAML settings."""

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from maglev_ros.control import (
    ControllerConfig,
    ControllerConfigError,
    LqrController,
    PdController,
    design_lqr,
    load_controller_config,
    steady_state,
)

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'controller.yaml'


@pytest.mark.parametrize('delay', [0, 1, 3])
@pytest.mark.parametrize('coil', [False, True])
@pytest.mark.parametrize('integral', [False, True])
def test_lqr_designs_stabilise_both_sets(v2_linear, v4_linear, delay, coil, integral):
    config = ControllerConfig(command_delay=delay, coil_dynamics=coil, integral=integral)
    for lin in (v2_linear.reduced(), v4_linear.reduced()):
        design = design_lqr(lin, config, tau=0.004 / 3.0)
        n = 10 + 4 * coil + 4 * delay + 3 * integral
        assert design.K.shape == (4, n) and design.A.shape == (n, n)
        assert design.stable
        # the open loop is unstable: the gain does the work
        assert np.max(np.abs(np.linalg.eigvals(design.A))) > 1.0


@pytest.mark.parametrize('delay', [1, 2, 5])
def test_delay_states_are_a_register_the_plant_reads_at_its_end(v2_linear, delay):
    """The augmented model equals the plant driven by the command of ``delay`` samples ago."""
    from maglev_ros.physics.discretization import zoh

    lin = v2_linear.reduced()
    config = ControllerConfig(command_delay=delay, sample_rate=1000.0)
    design = design_lqr(lin, config)
    phi, gamma = zoh(lin.A, lin.B, config.dt)
    rng = np.random.default_rng(0)
    u = rng.standard_normal((12, 4))
    x = np.zeros(10)
    xi = np.zeros(design.A.shape[0])
    xi[:10] = x = 1e-4 * rng.standard_normal(10)
    for k in range(12):
        xi = design.A @ xi + design.B @ u[k]
        x = phi @ x + gamma @ (u[k - delay] if k >= delay else np.zeros(4))
        assert np.allclose(xi[:10], x, rtol=1e-12, atol=1e-18)
        pending = [u[k - j] if k >= j else np.zeros(4) for j in range(delay)]
        assert np.allclose(xi[design.layout['c_prev']], np.concatenate(pending), atol=0)
    assert design.stable


def test_lqr_for_three_samples_of_delay_holds_where_commands_come_three_late(v2):
    """The whole loop (noisy sensors, coils), commands applied 3 samples late, 2 s."""
    from maglev_ros.control.closed_loop import make_closed_loop

    loop = make_closed_loop(v2, controller=ControllerConfig(command_delay=3))
    assert loop.command_delay == 3
    result = loop.run(2.0)
    assert not result.crashed
    tail = result.x[len(result.t) // 2 :, :3] - [0.0, 0.0, result.z_eq]
    assert np.all(np.sqrt(np.mean(tail**2, axis=0)) < 1e-4)


def test_steady_state_holds_an_offset(v2_linear):
    lin = v2_linear.reduced()
    p = np.array([2.5e-4, -1e-4, 5e-5])
    dx, u = steady_state(lin.A, lin.B, p)
    assert np.allclose(dx[:3], p, atol=1e-15)
    assert np.max(np.abs(lin.A @ dx + lin.B @ u)) < 1e-9
    assert np.all(np.abs(u) < 1.0)


def test_lqr_limits_and_watchdog(v2, v2_linear):
    ctrl = LqrController(v2, ControllerConfig(input_timeout=0.002, rearm_samples=3), v2_linear)
    x = v2_linear.x_eq.copy()
    x[0] += 2e-3  # far off: saturates
    c = ctrl.command(0.0, x, np.zeros(4))
    assert np.max(np.abs(c)) == 1.0 and ctrl.status().level == 'OK' and ctrl.saturated == 1
    assert c[0] < 0 < c[1]  # pushes back towards -x
    assert np.array_equal(ctrl.command(0.001), c)  # a missing estimate: hold
    assert np.array_equal(ctrl.command(0.0025), np.zeros(4))  # stale
    status = ctrl.status()
    assert status.level == 'ERROR' and 'no input for 2.5 ms' in status.message
    assert 'coils at zero current' in status.message and status.timeouts == 1
    x[0] = v2_linear.x_eq[0] + 1e-5
    for k in range(2):  # re-arming: still zero
        assert np.array_equal(ctrl.command(0.003 + 2e-4 * k, x, np.zeros(4)), np.zeros(4))
    assert 're-arming (2/3' in ctrl.status().message
    c = ctrl.command(0.0034, x, np.zeros(4))
    assert np.any(c != 0) and ctrl.status().level == 'OK'
    ctrl.set_enabled(False)
    assert np.array_equal(ctrl.command(0.0036, x, np.zeros(4)), np.zeros(4))
    assert ctrl.status().level == 'WARN' and 'disabled' in ctrl.status().message


def test_lqr_reference_feedforward(v2, v2_linear):
    ctrl = LqrController(v2, ControllerConfig(), v2_linear)
    target = v2_linear.x_eq[:3] + [2.5e-4, 0.0, 0.0]
    ctrl.set_reference(target)
    x = v2_linear.x_eq.copy()
    x[[0, 1, 2, 3, 4]] += ctrl._dx_ss[:5]
    ctrl._c_prev = ctrl._u_ss.copy()  # the pending command is the steady one too
    c = ctrl.command(0.0, x, ctrl._u_ss)
    assert np.allclose(c, ctrl._u_ss, atol=1e-9)  # at the set-point: only the feedforward
    assert abs(ctrl._u_ss[0] - -ctrl._u_ss[1]) < 1e-9 and ctrl._u_ss[0] < 0
    with pytest.raises(ValueError, match='reference must be 3 finite numbers'):
        ctrl.set_reference([0.0, np.nan, 0.0])


def test_pd_signs_and_magnet_presence(v2, v2_linear):
    pd = PdController(v2, ControllerConfig(mode='pd'), v2_linear)
    x = v2_linear.x_eq.copy()
    x[0] += 3e-5
    y = v2.measurement(x, np.zeros(4))
    c = pd.command(0.0, y, np.zeros(4))
    assert c[0] < 0 < c[1] and c[2] == 0 == c[3]  # Bx > 0 -> push to -x
    assert pd.status().level == 'OK'
    away = v2.measurement(x, np.zeros(4), with_magnet=False)
    assert np.array_equal(pd.command(2e-4, away, np.zeros(4)), np.zeros(4))
    assert pd.status().level == 'WARN' and 'no magnet' in pd.status().message


def test_yaml_holds_the_documented_defaults():
    from_file = load_controller_config(CONFIG)
    assert from_file == ControllerConfig()
    text = CONFIG.read_text()
    for f in fields(ControllerConfig):
        assert f'  {f.name}:' in text  # every setting is documented in the file


def test_bad_settings_name_the_value_and_the_file(tmp_path):
    with pytest.raises(ControllerConfigError, match='current_limit must be a finite number'):
        ControllerConfig(current_limit=0.0)
    with pytest.raises(ControllerConfigError, match='mode must be one of lqr, pd'):
        ControllerConfig(mode='mpc')
    for delay in (-1, 21, True, 1.5):
        with pytest.raises(ControllerConfigError, match='command_delay must be an integer from'):
            ControllerConfig(command_delay=delay)
    bad = tmp_path / 'c.yaml'
    bad.write_text('controller:\n  position_scal: 1.0e-4\n')
    with pytest.raises(ControllerConfigError, match=r'c\.yaml: unknown controller setting'):
        load_controller_config(bad)
    assert load_controller_config(CONFIG, current_limit=0.8).current_limit == 0.8


def test_lqr_latches_a_lost_magnet_until_enabled(v2, v2_linear):
    ctrl = LqrController(v2, ControllerConfig(), v2_linear)
    x = v2_linear.x_eq.copy()
    x[1] += 1e-5
    assert np.any(ctrl.command(0.0, x, np.zeros(4)) != 0)
    far = x.copy()
    far[1] += 3.5e-3  # beyond loss_distance (3 mm): no controller brings it back
    assert np.array_equal(ctrl.command(2e-4, far, np.zeros(4)), np.zeros(4))
    status = ctrl.status()
    assert status.level == 'ERROR' and not status.active
    assert 'magnet lost: estimate 3.5 mm from the equilibrium' in status.message
    assert 'coils at zero current' in status.message and 'enable' in status.message
    # latched: a good estimate alone does not re-arm it
    for k in range(20):
        assert np.array_equal(ctrl.command(4e-4 + 2e-4 * k, x, np.zeros(4)), np.zeros(4))
    assert ctrl.status().level == 'ERROR'
    nan = np.full(12, np.nan)
    ctrl.set_enabled(True)  # the operator's go-ahead
    assert np.any(ctrl.command(0.005, x, np.zeros(4)) != 0) and ctrl.status().level == 'OK'
    assert np.array_equal(ctrl.command(0.0052, nan, np.zeros(4)), np.zeros(4))  # NaN: lost
    ctrl.reset()
    assert np.any(ctrl.command(0.0054, x, np.zeros(4)) != 0)
