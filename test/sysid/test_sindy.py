"""SINDy with control (pysindy): a known system exactly, and the simulated magnet's states."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from maglev_ros.physics import linearize, make_model
from maglev_ros.sysid.sindy import eigenvalue_check, sindy, sindy_magnet

from .physics_runs import record

STATES = ('x', 'y', 'z', 'alpha', 'beta', 'vx', 'vy', 'vz', 'wx', 'wy')
INPUTS = ('i1', 'i2', 'i3', 'i4')


def forcing(t):
    return 0.8 * np.sin(1.3 * t) + 0.5 * np.sin(3.7 * t)


def duffing(t, s):
    """dx/dt = v, dv/dt = -x - 0.2 v - 0.5 x^3 + u(t)."""
    x, v = s
    return [v, -x - 0.2 * v - 0.5 * x**3 + forcing(t)]


TRUTH = {'x': {'v': 1.0}, 'v': {'x': -1.0, 'v': -0.2, 'x^3': -0.5, 'u': 1.0}}


@pytest.fixture(scope='module')
def duffing_run():
    dt = 0.01
    t = np.arange(0.0, 40.0, dt)
    sol = solve_ivp(duffing, (0.0, t[-1]), [1.0, 0.0], t_eval=t, rtol=1e-10, atol=1e-12)
    x = sol.y.T
    return (
        x,
        forcing(t)[:, None],
        dt,
        np.array([duffing(tk, s) for tk, s in zip(t, x, strict=True)]),
    )


def test_known_system_recovered_exactly(duffing_run):
    x, u, dt, x_dot = duffing_run
    exact = sindy(x, u, dt, degree=3, x_dot=x_dot, state_names='xv', input_names='u')
    differenced = sindy(x, u, dt, degree=3, state_names='xv', input_names='u')
    for state, truth in TRUTH.items():
        assert exact.terms(state) == pytest.approx(truth, abs=1e-9)
        assert set(differenced.terms(state)) == set(truth)
        assert differenced.terms(state) == pytest.approx(truth, rel=1e-3)
    assert str(exact).splitlines()[2] == '  d(v)/dt = -1.0000 x - 0.2000 v + 1.0000 u - 0.5000 x^3'


def test_inputs_must_match_states(duffing_run):
    x, u, dt, _ = duffing_run
    with pytest.raises(ValueError, match=r'experiment 1: states \(4000, 2\) and inputs'):
        sindy(x, u[:-1], dt)


@pytest.fixture(scope='module')
def magnet():
    """Closed loop, an independent +-0.3 A PRBS on each coil (held 20 samples), 4 s."""
    result, _ = record('all', 0.3, 0.05, 20000, 0)
    linear = linearize(make_model('maggy_v2'))
    return result, linear


def fit(states, result, linear):
    return sindy_magnet(states, result.currents, result.dt, linear)


def eigenvalue_errors(model, linear):
    """Name -> (physics, SINDy, relative error) of the unstable and the oscillatory pairs."""
    return {c.name: (c.physics, c.found, c.error) for c in eigenvalue_check(model, linear)}


def test_true_states_give_the_physics_eigenvalues_and_force_law(magnet, capsys):
    result, linear = magnet
    model = fit(result.x, result, linear)
    errors = eigenvalue_errors(model, linear)
    vz = model.terms('vz')
    # physics: the vertical force law's slope in z and per coil, in mm/s^2 per mm and per A
    iz, ivz = STATES.index('z'), STATES.index('vz')
    slope_z = linear.reduced().A[ivz, iz]
    slope_i = linear.reduced().B[ivz]
    with capsys.disabled():
        print('\n' + '\n'.join(model.equations(2)[5:8]))
        for name, (target, nearest, err) in errors.items():
            print(f'{name}: physics {target:.2f}, SINDy {nearest:.2f} 1/s ({100 * err:.2f} %)')
        print(f'd(vz)/dt: z {vz["z"]:.1f} (physics {slope_z:.1f}) 1/s^2, '
              f'i {vz["i1"]:.1f} (physics {slope_i[0] * 1e3:.1f}) mm/s^2/A')  # fmt: skip
    for _, _, err in errors.values():
        assert err < 0.10
    assert vz['z'] == pytest.approx(slope_z, rel=0.05)
    for k in range(4):
        assert vz[INPUTS[k]] == pytest.approx(slope_i[k] * 1e3, rel=0.05)


def test_estimator_estimates_give_the_slow_oscillation(magnet, capsys):
    """The KF's estimates (what the estimator publishes) instead of the true states.

    Measured (this record): slow oscillatory pair within 5.1 %, fast pair 11.4 %;
    the unstable pair is not recovered (no real positive eigenvalue: the
    estimates' velocities are the KF's, whose differences are dominated by its
    corrections).  Smoothed differences or decimation did not help (5-29 %,
    unstable pair still missing), so only the slow pair is asserted.
    """
    result, linear = magnet
    model = fit(result.estimate, result, linear)
    errors = eigenvalue_errors(model, linear)
    with capsys.disabled():
        for name, (target, nearest, err) in errors.items():
            print(f'estimates, {name}: physics {target:.2f}, SINDy {nearest:.2f} '
                  f'({100 * err:.1f} %)')  # fmt: skip
    assert errors['oscillatory (slow)'][2] < 0.10
