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

Time is wall time of one run each (the machine is shared: see docs/benchmarks.md).

Usage::

    python benchmarks/calibration.py            # about a minute (the plain run)
    python benchmarks/calibration.py --skip-plain
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--skip-plain', action='store_true', help='skip the per-sample baseline')
    args = parser.parse_args()
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
