"""Estimator cost per sample: our KF, EKF and UKF against filterpy's, in the same run.

Data: 2,000 samples (0.4 s at 5 kHz) of the V2 closed loop (KF + LQR, sensor
noise 0.1 mT, quantisation 0.098 mT, one sample of delay, coil dynamics),
recorded once; every filter then processes the same readings and currents.

Pairs (same model, same data, same order of operations):

* KF: ``KalmanEstimator.step`` (one compiled call per sample: freeze check,
  gated Joseph update, predict) vs ``filterpy.kalman.KalmanFilter``
  ``update`` + ``predict`` with the same F, B, H, Q, R (no gating, no freeze
  check: filterpy has neither).
* EKF: ``ExtendedEstimator.step`` vs ``filterpy.kalman.ExtendedKalmanFilter``
  driven by the same compiled model: ``ekf_measure`` gives h and its Jacobian
  to filterpy's ``update``, ``ekf_transition`` the mean (one RK4 step) and F
  to its ``predict``. The difference is filterpy's covariance algebra and
  call overhead against ours (one compiled call each for update and predict).
* UKF: ``UnscentedEstimator.step`` (filterpy's UKF plus our per-sensor gate:
  one more unscented transform through h) vs filterpy's
  ``UnscentedKalmanFilter`` ``update`` + ``predict`` alone with the same f, h.

Cost: the best of ``--repeat`` runs of CPU time (``time.thread_time``) per
sample, single-threaded BLAS. The 5 kHz budget is 200 us per sample for the
whole loop (simulator or driver, estimator, controller).

Usage::

    python benchmarks/estimator.py            # about a minute with a warm numba cache
    python benchmarks/estimator.py --markdown docs/estimator_bench.md
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from filterpy.kalman import (  # noqa: E402
    ExtendedKalmanFilter,
    KalmanFilter,
    MerweScaledSigmaPoints,
    UnscentedKalmanFilter,
)

from maglev_ros.control.closed_loop import make_closed_loop  # noqa: E402
from maglev_ros.estimation import EstimatorConfig, make_estimator  # noqa: E402
from maglev_ros.estimation.kernels import ekf_measure, ekf_transition  # noqa: E402
from maglev_ros.physics import linearize, make_model  # noqa: E402
from maglev_ros.physics.linearization import FD_STEP  # noqa: E402

N = 2000


def record(model, linear):
    """Record the readings and currents of a short closed-loop run, (N, 9), (N, 4)."""
    loop = make_closed_loop(model, linear=linear)
    ys, cs = [], []
    sim, est, ctrl = loop.simulator, loop.estimator, loop.controller
    y = sim.reset()
    pending = np.zeros(4)
    for k in range(N):
        i = sim.currents
        ys.append(y)
        cs.append(i)
        command = ctrl.command(k * sim.dt, est.step(y, i), i)
        pending, applied = command, pending
        y = sim.step(applied)
    return np.array(ys), np.array(cs)


def best_cpu(run, repeat: int) -> float:
    """Return the best CPU time of ``repeat`` runs, s."""
    best = np.inf
    for _ in range(repeat):
        t = time.thread_time()
        run()
        best = min(best, time.thread_time() - t)
    return best


def ours(model, linear, kind, ys, cs):
    est = make_estimator(model, EstimatorConfig(filter=kind), linear=linear)

    def run():
        est.reset()
        for y, i in zip(ys, cs, strict=True):
            est.step(y, i)

    return run


def filterpy_kf(model, linear, ys, cs):
    est = make_estimator(model, EstimatorConfig(filter='kf'), linear=linear)
    kf = KalmanFilter(dim_x=est.n_states, dim_z=est.n_outputs, dim_u=est.n_inputs)
    kf.F, kf.B, kf.H, kf.Q, kf.R = est.F, est.B, est.H, est.Q, np.diag(est.r_diag)
    zs = [est.measurement(y, i) for y, i in zip(ys, cs, strict=True)]
    us = [i - est.u_eq for i in cs]

    def run():
        kf.x = np.zeros(est.n_states)
        kf.P = est.initial_covariance()
        for z, u in zip(zs, us, strict=True):
            kf.update(z)
            kf.predict(u=u)

    return run


def filterpy_ekf(model, linear, ys, cs):
    est = make_estimator(model, EstimatorConfig(filter='ekf'), linear=linear)
    n = est.n_states
    ekf = ExtendedKalmanFilter(dim_x=n, dim_z=est.n_outputs, dim_u=est.n_inputs)
    ekf.Q, ekf.R = est.Q, np.diag(est.r_diag)
    x_eq, red, dt = est._x_eq, est.reduced, est.dt
    f_args, h_args = est._f_args, est._h_args
    step = {'x': None}

    def predict_x(u=0):  # the mean from the same compiled RK4 step
        return step['x']

    ekf.predict_x = predict_x

    def run():
        ekf.x = np.zeros(n)
        ekf.P = est.initial_covariance()
        for y, i in zip(ys, cs, strict=True):
            u = np.ascontiguousarray(i)
            h, jac = ekf_measure(ekf.x, u, x_eq, red, FD_STEP, *h_args)
            ekf.update(y, lambda x, jac=jac: jac, lambda x, h=h: h)
            step['x'], ekf.F = ekf_transition(ekf.x, u, x_eq, red, dt, FD_STEP, *f_args)
            ekf.predict()

    return run


def filterpy_ukf(model, linear, ys, cs):
    est = make_estimator(model, EstimatorConfig(filter='ukf'), linear=linear)
    n = est.n_states
    points = MerweScaledSigmaPoints(n, alpha=1.0, beta=2.0, kappa=0.0)
    ukf = UnscentedKalmanFilter(
        dim_x=n, dim_z=est.n_outputs, dt=est.dt, hx=est._hx, fx=est._fx, points=points
    )
    ukf.Q, ukf.R = est.ukf.Q, est.ukf.R

    def run():
        ukf.x = np.zeros(n)
        ukf.P = est.initial_covariance()
        ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)
        for y, i in zip(ys, cs, strict=True):
            u = np.ascontiguousarray(i)
            ukf.update(y, u=u)
            ukf.predict(u=u)

    return run


def main(argv=None) -> int:
    """Run the comparison and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=3, help='runs per filter (best counts)')
    parser.add_argument('--ukf-samples', type=int, default=400, help='samples for the UKFs')
    parser.add_argument('--markdown', help='also write the table to this file')
    args = parser.parse_args(argv)
    model = make_model('maggy_v2')
    linear = linearize(model)
    print(f'recording {N} samples of the V2 closed loop ...', flush=True)
    ys, cs = record(model, linear)
    rows = []
    for kind, peer in (('kf', filterpy_kf), ('ekf', filterpy_ekf), ('ukf', filterpy_ukf)):
        n = args.ukf_samples if kind == 'ukf' else N
        mine = ours(model, linear, kind, ys[:n], cs[:n])
        theirs = peer(model, linear, ys[:n], cs[:n])
        mine()  # compile / warm up
        theirs()
        t_ours = best_cpu(mine, args.repeat) / n
        t_peer = best_cpu(theirs, args.repeat) / n
        rows.append((kind, t_ours, t_peer))
        print(
            f'{kind.upper():3s}  ours {t_ours * 1e6:8.1f} us/sample  '
            f'filterpy {t_peer * 1e6:8.1f} us/sample  ratio {t_peer / t_ours:6.2f}x  '
            f'({t_ours * 5000 * 100:.0f} % of one core at 5 kHz)',
            flush=True,
        )
    lines = [
        '| filter | ours (us/sample) | filterpy (us/sample) | filterpy / ours '
        '| share of one core at 5 kHz |',
        '|---|---|---|---|---|',
    ]
    for kind, t_ours, t_peer in rows:
        lines.append(
            f'| {kind.upper()} | {t_ours * 1e6:.1f} | {t_peer * 1e6:.1f} | {t_peer / t_ours:.2f}x '
            f'| {t_ours * 5000 * 100:.0f} % |'
        )
    table = '\n'.join(lines)
    print(table)
    if args.markdown:
        with open(args.markdown, 'w') as f:
            f.write(table + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
