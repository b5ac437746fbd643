"""Issue 9, "done when" 1, on the ROS-free loop with the objects the nodes use.

Set-up: V2 and V4, true torque, rigid kinematics, sensor noise 0.1 mT per axis,
quantisation 0.098 mT, one sample of sensor delay, coil dynamics on, 1.0 A
limit, commands taking effect one sample late (the board). Long runs are
shared between tests through module-scoped fixtures.
"""

import dataclasses

import numpy as np
import pytest

from maglev_ros.control import ControllerConfig
from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.estimation import EstimatorConfig
from maglev_ros.physics import SensorFreeze, load_parameters, make_model

#: s of simulated time for the KF + LQR holds (those of docs/closed_loop.md's table)
HOLD = {'maggy_v2': 60.0, 'maggy_v4': 10.0}
# 60 s at 5 kHz is 300k loop steps: about 25 s on an idle core, several minutes on a
# loaded CI machine; the suite's 300 s per-test timeout is raised for these tests
pytestmark = pytest.mark.timeout(1800)
#: initial offset (m, each of x, y, z) and tilt (rad, alpha and beta) per parameter set
START = {'maggy_v2': (0.5e-3, np.deg2rad(1.0)), 'maggy_v4': (0.3e-3, np.deg2rad(0.5))}
MM = 1e-3


def _start(loop, name, scale=1.0):
    offset, tilt = START[name]
    x0 = loop.simulator.model.hover_state(loop.z_eq)
    x0[:3] += scale * offset
    x0[3:5] = scale * tilt
    return x0


def _model(name, request):
    return request.getfixturevalue('v2' if name == 'maggy_v2' else 'v4')


def _linear(name, request):
    return request.getfixturevalue('v2_linear' if name == 'maggy_v2' else 'v4_linear')


@pytest.fixture(scope='module', params=['maggy_v2', 'maggy_v4'])
def hold_run(request):
    name = request.param
    loop = make_closed_loop(_model(name, request), linear=_linear(name, request))
    return name, loop.run(HOLD[name], x0=_start(loop, name))


def test_settles_and_holds(hold_run):
    name, r = hold_run
    assert not r.crashed, r.reason
    settle = r.settle_time(threshold=0.1 * MM, window=0.1)
    assert settle < 1.0, f'{name}: settled at {settle} s'
    rms, worst = r.hold(settle)
    assert r.t[-1] - settle > HOLD[name] - 1.5
    assert np.all(rms < 0.1 * MM), f'{name}: RMS {rms * 1e6} um'
    assert np.all(worst < 0.4 * MM), f'{name}: excursion {worst * 1e6} um'


def test_estimator_is_consistent(hold_run):
    name, r = hold_run
    settle = r.settle_time()
    inside = r.consistency(settle)
    assert np.all(inside >= 0.99), f'{name}: within 3 sigma {inside}'
    total, (low, high) = r.nis_average(settle)
    assert low <= total <= high, f'{name}: NIS {total} outside [{low}, {high}]'
    _, windows = r.nis_windows(settle, window=500)
    assert np.mean(windows) >= 0.97, f'{name}: {np.mean(windows):.3f} of 0.1 s windows in band'


@pytest.mark.parametrize('name', ['maggy_v2', 'maggy_v4'])
def test_tracks_a_step_of_the_x_reference(name, request):
    loop = make_closed_loop(_model(name, request), linear=_linear(name, request))
    x_eq = loop.estimator.x_eq[:3]
    step_at, step = 0.5, 0.25 * MM

    def reference(t):
        return x_eq + [step, 0.0, 0.0] if t >= step_at else x_eq

    r = loop.run(3.5, reference=reference)
    assert not r.crashed, r.reason
    err = r.x[:, 0] - r.reference[:, 0]
    # within 0.5 s: the 20 ms moving mean of x reaches 90 % of the step
    n = int(round(0.02 / r.dt))
    smooth = np.convolve(r.x[:, 0] - x_eq[0], np.ones(n) / n, mode='same')
    reached = r.t[(r.t >= step_at) & (smooth >= 0.9 * step)]
    assert reached.size and reached[0] - step_at < 0.5, f'{name}: reached at {reached[:1]}'
    # afterwards the mean error is below 50 um
    after = r.t >= step_at + 0.5
    assert abs(np.mean(err[after])) < 50e-6, f'{name}: mean error {np.mean(err[after]) * 1e6} um'
    assert np.sqrt(np.mean(err[after] ** 2)) < 0.1 * MM


@pytest.mark.parametrize('name', ['maggy_v2', 'maggy_v4'])
def test_holds_through_a_frozen_sensor_and_names_it(name, request):
    freeze = SensorFreeze(schedule=((1, 1.0, 0.1),))
    loop = make_closed_loop(_model(name, request), linear=_linear(name, request), freeze=freeze)
    r = loop.run(2.0, x0=_start(loop, name))
    assert not r.crashed, r.reason
    rms, worst = r.hold(0.8)
    assert np.all(rms < 0.1 * MM) and np.all(worst < 0.4 * MM), (rms, worst)
    during = (r.t >= 1.0 + 4 * r.dt) & (r.t < 1.1)
    # sensor 1 throughout; the others at most a sample each: a still magnet's quantised
    # readings repeat freeze_samples times by chance (README: ~1 in 1e5 samples per sensor)
    assert np.all(r.frozen[during, 1])
    assert np.all(np.sum(r.frozen[during][:, [0, 2]], axis=0) <= 1)
    assert any('frozen sensor_1 at t = 1.00' in m for m in r.messages), r.messages
    assert np.sum(r.frozen[:, 1]) < 0.1 / r.dt + 10


@pytest.mark.parametrize('name', ['maggy_v2', 'maggy_v4'])
def test_a_cut_estimator_input_makes_the_controller_safe(name, request):
    loop = make_closed_loop(_model(name, request), linear=_linear(name, request))
    timeout = loop.controller.config.input_timeout
    r = loop.run(1.2, x0=_start(loop, name), cut=(1.0, 0.05))
    safe = (r.t > 1.0 + timeout + r.dt) & (r.t < 1.05)
    assert safe.any() and np.all(r.command[safe] == 0.0)
    assert np.all(r.level[safe] == 'ERROR')
    assert any('controller ERROR: input stale: no input for' in m for m in r.messages)
    assert any('coils at zero current' in m for m in r.messages)
    before = (r.t > 0.9) & (r.t < 1.0)
    assert np.all(np.abs(r.command[before]).max(axis=1) > 0)


def test_after_a_cut_v2_re_arms_and_holds_and_v4_is_lost_safely(v2, v2_linear, v4, v4_linear):
    # V2 (x/y modes e-fold in 34 ms) drifts ~0.15 mm in the 50 ms at zero current: recovered
    loop = make_closed_loop(v2, linear=v2_linear)
    rearm = loop.controller.config.rearm_samples
    r = loop.run(2.0, x0=_start(loop, 'maggy_v2'), cut=(1.0, 0.05))
    assert not r.crashed, r.reason
    back = r.t[(r.t >= 1.05) & (r.level == 'OK')]
    assert back.size and back[0] - 1.05 < (rearm + 1) * r.dt, back[:1]
    rms, worst = r.hold(1.5)
    assert np.all(rms < 0.1 * MM) and np.all(worst < 0.4 * MM), (rms, worst)
    # V4 (18 ms) is 1-2 mm off when the input returns: beyond recovery; the controller
    # sees the estimate leave (loss_distance) and leaves the coils at zero before the
    # magnet touches the base
    loop = make_closed_loop(v4, linear=v4_linear)
    r = loop.run(2.0, x0=_start(loop, 'maggy_v4'), cut=(1.0, 0.05))
    assert r.crashed and 1.05 < r.t[-1] < 1.2, r.reason
    lost = [m for m in r.messages if 'magnet lost' in m]
    assert lost, r.messages
    at = float(lost[0].split(' at t = ')[1].split(' s')[0])
    assert 1.05 < at < r.t[-1]
    assert np.all(r.command[r.t > at] == 0.0)


@pytest.mark.parametrize('name', ['maggy_v2', 'maggy_v4'])
@pytest.mark.parametrize(
    ('polarization', 'mass'), [(1.1, 1.1), (0.9, 0.9), (1.1, 0.9), (0.9, 1.1)]
)
def test_holds_with_model_mismatch(name, polarization, mass, request):
    believed = _model(name, request)
    p = load_parameters(name)
    magnet = dataclasses.replace(
        p.magnet, polarization=p.magnet.polarization * polarization, mass=p.magnet.mass * mass
    )
    plant = make_model(p.replace(magnet=magnet, solenoid_radius_correction=believed.correction))
    loop = make_closed_loop(
        believed,
        plant=plant,
        estimator=EstimatorConfig(bias_states=True),
        linear=_linear(name, request),
    )
    r = loop.run(10.0, x0=_start(loop, name, scale=0.0))
    assert not r.crashed, r.reason
    rms, worst = r.hold(1.0)
    assert np.all(rms < 0.2 * MM), f'RMS {rms * 1e6} um'
    assert np.all(worst < 0.8 * MM), f'excursion {worst * 1e6} um'


@pytest.mark.parametrize(('kind', 'duration'), [('ekf', 10.0), ('ukf', 2.0)])
def test_nonlinear_filters_settle_and_hold_v2(kind, duration, v2, v2_linear):
    loop = make_closed_loop(v2, estimator=EstimatorConfig(filter=kind), linear=v2_linear)
    r = loop.run(duration, x0=_start(loop, 'maggy_v2'))
    assert not r.crashed, r.reason
    settle = r.settle_time()
    assert settle < 1.0
    rms, worst = r.hold(settle)
    assert np.all(rms < 0.1 * MM) and np.all(worst < 0.4 * MM), (rms, worst)


def test_pd_levitates_v2_from_the_offset(v2, v2_linear):
    loop = make_closed_loop(v2, controller=ControllerConfig(mode='pd'), linear=v2_linear)
    r = loop.run(5.0, x0=_start(loop, 'maggy_v2'))
    assert not r.crashed, r.reason
    late = r.t >= 2.0
    err = r.position_error()[late]
    # x and y are held near the centre; z (not controlled by the PD) stays in its well
    assert np.all(np.sqrt(np.mean(err[:, :2] ** 2, axis=0)) < 0.3 * MM)
    assert np.max(np.abs(err[:, 2])) < 1.0 * MM
