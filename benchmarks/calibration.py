"""Benchmark the static calibration against plain ``scipy.optimize.least_squares``.

Problem: a Maggy V2 plant whose parameters differ from nominal (coil gains
+-2-3 %, sensor positions by 0.1-0.3 mm, a sensor gain, an offset, a permanent
magnet's polarisation), simulated with the magnet absent, 0.1 mT sensor noise and
one sample of sensor delay: 25,000 samples of the 9 field channels against the 4
coil currents (random levels held 5 ms). Ten free parameters: ``coil*.gain``,
``sensor1.x``, ``sensor2.y``, ``sensor0.z``, ``sensor1.gain_z``,
``sensor0.offset_z``, ``pm0.polarization``. All three solvers start at the
nominal set, with the same bounds, scaling, delay and estimation samples.

* **ours**: :func:`maglev_ros.greybox.calibrate_static` (the whole call:
  identifiability check, fit, covariance and validation): residuals reduced
  to the regression moments, Jacobian from central differences of the affine
  features.
* **plain**: ``least_squares(..., jac='2-point')`` on the full residual
  ``y_i - h(x, u_i; theta)``, the model evaluated per sample with
  ``MaggyModel.measurement`` (what one writes with the model's public API).
* **plain, vectorised**: the same, but the prediction uses the affine
  structure (``[1, u] @ features``): full 225,000-residual vector,
  finite-difference Jacobian by scipy.

Dynamic part (``--dynamic``): a V2 plant whose magnet is 4 % heavier and 3 %
weaker than nominal, held by the nominal KF + LQR in the ROS-free closed loop
with a random binary excitation (0.05 A per coil), 0.1 mT noise, 0.098 mT
quantisation, one sample of sensor delay: 2 s at 5 kHz, the first half for
estimation. Free: ``magnet.mass``, ``magnet.polarization``.

* **ours**: :func:`maglev_ros.greybox.calibrate_dynamic` (whole call: delay
  search, identifiability, fit, covariance, validation): linearised model,
  exact ZOH, stationary Kalman predictor run by a compiled loop, central
  differences.
* **plain**: ``least_squares(..., jac='2-point')`` on the same prediction
  errors written with the public API (``linearize``, ``zoh``,
  ``solve_discrete_are``) and the predictor as a numpy loop over the samples.
* **ours (nonlinear)**: ``calibrate_dynamic(..., form='nonlinear')``: the full
  nonlinear model's predictor with the Kalman gain of its linearisation, one
  compiled loop (RK4, the measured currents interpolated), central differences.
* **plain (nonlinear)**: ``least_squares(..., jac='2-point')`` on the same
  nonlinear predictor written with the public API (``MaggyModel.dynamics`` and
  ``.measurement`` per RK4 stage in a Python loop; the gain from ``linearize``,
  ``zoh``, ``solve_discrete_are``), scipy's default step and ours.
* **closed-loop simulation**: :func:`maglev_ros.greybox.calibrate_closed_loop`
  on the first 0.4 s (the older nonlinear form), for its cost and precision.

``--many``: the nonlinear and linear forms on a plant off nominal in six
parameters at once (mass +3 %, magnet polarisation -2 %, coil gains +2, -2,
+1.5, -1 %), all six free, 2 s.

Time is wall time of one run each (the machine is shared: see docs/benchmarks.md).

Usage::

    python benchmarks/calibration.py            # about a minute (the plain run)
    python benchmarks/calibration.py --skip-plain
    python benchmarks/calibration.py --dynamic  # the dynamic part only (a few minutes)
    python benchmarks/calibration.py --many     # six dynamic parameters at once
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from maglev_ros.greybox import StaticExperiment, calibrate_static, parameter_vector  # noqa: E402
from maglev_ros.physics import (  # noqa: E402
    MaggyModel,
    SensorEffects,
    Simulator,
    load_parameters,
)

FREE = [
    'coil*.gain',
    'sensor1.x',
    'sensor2.y',
    'sensor0.z',
    'sensor1.gain_z',
    'sensor0.offset_z',
    'pm0.polarization',
]
N = 25_000
SPLIT = 0.5  # the calibration uses the first half of 2 N samples: N samples


def make_problem():
    vector = parameter_vector(load_parameters('maggy_v2'))
    nominal = vector.nominal
    truth = {
        'coil0.gain': 1.03,
        'coil1.gain': 0.97,
        'coil2.gain': 1.02,
        'coil3.gain': 0.985,
        'sensor1.x': nominal['sensor1.x'] + 3e-4,
        'sensor2.y': nominal['sensor2.y'] - 2e-4,
        'sensor0.z': nominal['sensor0.z'] + 1e-4,
        'sensor1.gain_z': 1.02,
        'sensor0.offset_z': 5e-4,
        'pm0.polarization': 1.1 * 1.03,
    }
    rng = np.random.default_rng(7)
    levels = rng.uniform(-1.0, 1.0, (2 * N // 25 + 1, 4))
    drives = np.repeat(levels, 25, axis=0)[: 2 * N]
    sim = Simulator(
        MaggyModel(vector.apply(truth)),
        sensor=SensorEffects(noise_rms=1e-4, delay_samples=1),
        seed=3,
        magnet='absent',
    )
    run = sim.run(drives)
    exp = StaticExperiment(run.currents, run.y, 'absent', 'plant, magnet absent')
    return vector.with_free(FREE), exp, truth


def plain(vector, exp, vectorised: bool):
    """Plain least_squares, scipy's finite differences, full residual."""
    est, _ = exp.split(SPLIT)
    u, y = est.u[:-1], est.y[1:]  # one sample of delay, as ours finds
    specs = vector.free_specs
    center = np.array([s.nominal for s in specs])
    scale = np.array([s.scale for s in specs])
    lower = np.array([(s.lower - s.nominal) / s.scale for s in specs])
    upper = np.array([(s.upper - s.nominal) / s.scale for s in specs])
    x0 = np.array([0.0, 0.0, 0.03] + [0.0] * 9)
    units = np.vstack([np.zeros(4), np.eye(4)])
    z_reg = np.hstack([np.ones((u.shape[0], 1)), u])
    calls = [0]

    def residual(z):
        calls[0] += 1
        model = MaggyModel(vector.apply(vector.values(center + scale * z)))
        if vectorised:
            rows = np.array([model.measurement(x0, e, with_magnet=False) for e in units])
            rows[1:] -= rows[0]
            yhat = z_reg @ rows
        else:
            yhat = np.array([model.measurement(x0, ui, with_magnet=False) for ui in u])
        return ((y - yhat) / 1e-4).ravel()

    start = time.perf_counter()
    sol = least_squares(
        residual,
        np.zeros(len(specs)),
        jac='2-point',
        bounds=(lower, upper),
        method='trf',
        x_scale=1.0,
    )
    seconds = time.perf_counter() - start
    return seconds, dict(zip(vector.free_names, center + scale * sol.x, strict=True)), calls[0]


DYN_TRUTH = {'magnet.mass': 0.077 * 1.04, 'magnet.polarization': -1.0 * 0.97}
DYN_FREE = ['magnet.mass', 'magnet.polarization']
DYN_SECONDS = 2.0


def levitation_problem(duration: float = DYN_SECONDS):
    """Closed-loop levitation record of the perturbed plant (experiment, excitation)."""
    from maglev_ros.control.closed_loop import make_closed_loop
    from maglev_ros.excitation.signals import random_binary
    from maglev_ros.greybox import LevitationExperiment

    vector = parameter_vector(load_parameters('maggy_v2'))
    n = int(round(duration * 5000))
    exc = np.column_stack([random_binary(n, 0.05, (0.0, 0.2), seed=10 + j) for j in range(4)])
    loop = make_closed_loop(vector.base, plant=vector.apply(DYN_TRUTH), seed=1)
    run = loop.run(duration, excitation=exc)
    exp = LevitationExperiment(run.currents, run.readings, 'levitation', 2e-4)
    return vector.with_free(DYN_FREE), exp, exc


def plain_dynamic(vector, exp, delay: int, sigma: np.ndarray, diff_step=None):
    """Plain least_squares with scipy's finite differences; numpy predictor loop."""
    from scipy.linalg import solve_discrete_are

    from maglev_ros.physics import find_equilibria, linearize, zoh

    est, _ = exp.split(0.5)
    specs = vector.free_specs
    center = np.array([s.nominal for s in specs])
    scale = np.array([s.scale for s in specs])
    lower = np.array([(s.lower - s.nominal) / s.scale for s in specs])
    upper = np.array([(s.upper - s.nominal) / s.scale for s in specs])
    calls = [0]

    def residual(z):
        calls[0] += 1
        model = MaggyModel(vector.apply(vector.values(center + scale * z)))
        eq = find_equilibria(model)[0]
        lin = linearize(model, model.hover_state(eq.z)).reduced()
        ad, bd = zoh(lin.A, lin.B, est.Ts)
        c, d = lin.C, lin.D
        r = np.diag(sigma**2)
        p = solve_discrete_are(ad.T, c.T, 1e-6 * bd @ bd.T + 1e-30 * np.eye(10), r)
        k = ad @ p @ c.T @ np.linalg.inv(c @ p @ c.T + r)
        x = np.zeros(10)
        out = np.empty((est.samples - delay, c.shape[0]))
        for i in range(out.shape[0]):
            e = est.y[i + delay] - lin.y_eq - c @ x - d @ est.u[i]
            out[i] = e
            x = ad @ x + bd @ est.u[i] + k @ e
        return (out[100:] / sigma).ravel()

    start = time.perf_counter()
    sol = least_squares(
        residual,
        np.zeros(len(specs)),
        jac='2-point',
        bounds=(lower, upper),
        method='trf',
        diff_step=diff_step,
    )
    seconds = time.perf_counter() - start
    return seconds, dict(zip(vector.free_names, center + scale * sol.x, strict=True)), calls[0]


def plain_nonlinear(vector, exp, delay: int, sigma: np.ndarray, diff_step=None):
    """Plain least_squares, 2-point, on the nonlinear predictor in a Python loop."""
    from scipy.linalg import solve_discrete_are

    from maglev_ros.physics import find_equilibria, linearize, zoh
    from maglev_ros.physics.linearization import REDUCED_STATES

    est, _ = exp.split(0.5)
    specs = vector.free_specs
    center = np.array([s.nominal for s in specs])
    scale = np.array([s.scale for s in specs])
    lower = np.array([(s.lower - s.nominal) / s.scale for s in specs])
    upper = np.array([(s.upper - s.nominal) / s.scale for s in specs])
    rows = list(REDUCED_STATES)
    calls = [0]
    h = est.Ts

    def residual(z):
        calls[0] += 1
        model = MaggyModel(vector.apply(vector.values(center + scale * z)))
        eq = find_equilibria(model)[0]
        x = model.hover_state(eq.z)
        lin = linearize(model, x).reduced()
        ad, bd = zoh(lin.A, lin.B, h)
        c = lin.C
        r = np.diag(sigma**2)
        p = solve_discrete_are(ad.T, c.T, 1e-6 * bd @ bd.T + 1e-30 * np.eye(10), r)
        k = ad @ p @ c.T @ np.linalg.inv(c @ p @ c.T + r)
        out = np.empty((est.samples - delay, c.shape[0]))
        for i in range(out.shape[0]):
            u0, u1 = est.u[i], est.u[min(i + 1, est.samples - 1)]
            um = 0.5 * (u0 + u1)
            e = est.y[i + delay] - model.measurement(x, u0)
            out[i] = e
            k1 = model.dynamics(x, u0)
            k2 = model.dynamics(x + 0.5 * h * k1, um)
            k3 = model.dynamics(x + 0.5 * h * k2, um)
            k4 = model.dynamics(x + h * k3, u1)
            x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
            x[rows] += k @ e
        return (out[100:] / sigma).ravel()

    start = time.perf_counter()
    sol = least_squares(
        residual,
        np.zeros(len(specs)),
        jac='2-point',
        bounds=(lower, upper),
        method='trf',
        diff_step=diff_step,
    )
    seconds = time.perf_counter() - start
    return seconds, dict(zip(vector.free_names, center + scale * sol.x, strict=True)), calls[0]


MANY_TRUTH = {
    'magnet.mass': 0.077 * 1.03,
    'magnet.polarization': -0.98,
    'coil0.gain': 1.02,
    'coil1.gain': 0.98,
    'coil2.gain': 1.015,
    'coil3.gain': 0.99,
}


def many() -> None:
    """Six dynamic parameters at once, nonlinear and linear forms."""
    from maglev_ros.control.closed_loop import make_closed_loop
    from maglev_ros.excitation.signals import random_binary
    from maglev_ros.greybox import LevitationExperiment, calibrate_dynamic

    vector = parameter_vector(load_parameters('maggy_v2'))
    n = int(round(DYN_SECONDS * 5000))
    exc = np.column_stack([random_binary(n, 0.05, (0.0, 0.2), seed=10 + j) for j in range(4)])
    loop = make_closed_loop(vector.base, plant=vector.apply(MANY_TRUTH), seed=1)
    run = loop.run(DYN_SECONDS, excitation=exc)
    exp = LevitationExperiment(run.currents, run.readings, 'levitation', 2e-4)
    free = vector.with_free(list(MANY_TRUTH))
    for form in ('nonlinear', 'linear'):
        start = time.perf_counter()
        cal = calibrate_dynamic(free, [exp], delay=1, form=form)
        seconds = time.perf_counter() - start
        print(f'{form}: {seconds:.2f} s ({cal.evaluations} model evaluations)')
        for name in cal.names:
            true, est, sd = MANY_TRUTH[name], cal.estimate[name], cal.std[name]
            print(
                f'  {name:<20} {est:.6g} +- {sd:.3g} (true {true:.6g}): '
                f'{100 * (est / true - 1):+.3f} %, {(est - true) / sd:+.2f} std'
            )
        for a, b, r in cal.correlated:
            print(f'  correlated: {a} ~ {b}, r = {r:+.3f}')
        print(
            f'  validation RMS nominal {1e3 * cal.validation_nominal[0].total_rms:.4f} mT, '
            f'calibrated {1e3 * cal.validation_calibrated[0].total_rms:.4f} mT'
        )


def dynamic(skip_plain: bool) -> None:
    from maglev_ros.greybox import LoopSetup, calibrate_closed_loop, calibrate_dynamic

    start = time.perf_counter()
    vector, exp, exc = levitation_problem()
    print(f'levitation record: {exp.samples} samples ({time.perf_counter() - start:.1f} s)')
    calibrate_dynamic(vector, [exp], delay=1)  # compile/load kernels
    start = time.perf_counter()
    cal = calibrate_dynamic(vector, [exp])
    ours = time.perf_counter() - start
    worst = max(abs(cal.estimate[n] - DYN_TRUTH[n]) / cal.std[n] for n in cal.names)
    rel = max(abs(cal.estimate[n] / DYN_TRUTH[n] - 1) for n in cal.names)
    print(
        f'ours (linear)        {ours:8.2f} s  ({cal.evaluations} model evaluations), worst '
        f'|estimate - truth| = {worst:.2f} std, {100 * rel:.3f} %'
    )
    if not skip_plain:
        # scipy's default step (~1e-8 relative) differentiates the linearisation's
        # finite-difference noise; a step of 1e-2 (in parameter scales) is ours too
        for label, step in (('default step', None), ('step 1e-2', 1e-2)):
            seconds, est, calls = plain_dynamic(
                vector, exp, cal.delays[0], cal.noise[0], diff_step=step
            )
            diff = max(abs(est[n] - cal.estimate[n]) / cal.std[n] for n in cal.names)
            print(
                f'plain (2-point, {label}, numpy loop) {seconds:8.2f} s  ({calls} residual '
                f'evaluations), ratio {seconds / ours:6.1f}x; max |plain - ours| / std = '
                f'{diff:.3f}'
            )
    calibrate_dynamic(vector, [exp], delay=1, form='nonlinear')  # compile/load kernels
    start = time.perf_counter()
    nl = calibrate_dynamic(vector, [exp], form='nonlinear')
    ours_nl = time.perf_counter() - start
    worst = max(abs(nl.estimate[n] - DYN_TRUTH[n]) / nl.std[n] for n in nl.names)
    rel = max(abs(nl.estimate[n] / DYN_TRUTH[n] - 1) for n in nl.names)
    print(
        f'ours (nonlinear)     {ours_nl:8.2f} s  ({nl.evaluations} model evaluations), worst '
        f'|estimate - truth| = {worst:.2f} std, {100 * rel:.3f} %'
    )
    if not skip_plain:
        for label, step in (('default step', None), ('step 1e-2', 1e-2)):
            seconds, est, calls = plain_nonlinear(
                vector, exp, nl.delays[0], nl.noise[0], diff_step=step
            )
            diff = max(abs(est[n] - nl.estimate[n]) / nl.std[n] for n in nl.names)
            rel = max(abs(est[n] / DYN_TRUTH[n] - 1) for n in nl.names)
            print(
                f'plain nonlinear (2-point, {label}, Python loop) {seconds:8.2f} s  ({calls} '
                f'residual evaluations), ratio {seconds / ours_nl:6.1f}x; max |plain - ours| '
                f'/ std = {diff:.3f}; worst |estimate - truth| {100 * rel:.3f} %'
            )
    short = 2000
    from maglev_ros.greybox import LevitationExperiment

    head = LevitationExperiment(exp.u[:short], exp.y[:short], 'levitation, 0.4 s', exp.Ts)
    start = time.perf_counter()
    fit = calibrate_closed_loop(vector, head, LoopSetup(vector.base, exc[:short]))
    seconds = time.perf_counter() - start
    rel = max(abs(fit.estimate[n] / DYN_TRUTH[n] - 1) for n in fit.names)
    print(
        f'nonlinear (closed-loop simulation, 0.4 s) {seconds:8.2f} s  ({fit.simulations} '
        f'simulations), worst |estimate - truth| {100 * rel:.3f} %'
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--skip-plain', action='store_true', help='skip the per-sample baseline')
    parser.add_argument('--dynamic', action='store_true', help='the dynamic calibration only')
    parser.add_argument('--many', action='store_true', help='six dynamic parameters at once')
    args = parser.parse_args()
    if args.many:
        many()
        return
    if args.dynamic:
        dynamic(args.skip_plain)
        return
    vector, exp, truth = make_problem()
    MaggyModel(vector.apply({})).measurement(np.zeros(12), np.zeros(4))  # compile/load kernels
    print(f'{N} estimation samples x 9 channels, {len(vector.free_names)} free parameters')

    start = time.perf_counter()
    cal = calibrate_static(vector, [exp], split=SPLIT)
    ours = time.perf_counter() - start
    worst = max(abs(cal.estimate[n] - truth[n]) / cal.std[n] for n in cal.names)
    print(
        f'ours                 {ours:8.2f} s  ({cal.seconds:.2f} s fit, {cal.evaluations} '
        f'model evaluations), worst |estimate - truth| / std = {worst:.2f}'
    )
    rows = [('plain, vectorised', True)]
    if not args.skip_plain:
        rows.append(('plain, per sample', False))
    for label, vectorised in rows:
        seconds, est, calls = plain(vector, exp, vectorised)
        diff = max(abs(est[n] - cal.estimate[n]) / cal.std[n] for n in cal.names)
        print(
            f'{label:<20} {seconds:8.2f} s  ({calls} residual evaluations), ratio '
            f'{seconds / ours:6.1f}x; max |plain - ours| / std = {diff:.3f}'
        )
    verdict = 'meets' if ours <= 10.0 else 'misses'
    print(f'target: static calibration <= 10 s: {ours:.2f} s, {verdict} it')


if __name__ == '__main__':
    main()
