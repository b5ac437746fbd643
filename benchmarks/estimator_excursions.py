"""Large excursions: from which initial x offset each filter converges, controller in the loop.

For each parameter set and filter (KF, EKF, UKF; defaults) the closed loop of
``make_closed_loop`` (lab noise, sensor delay, coil dynamics, the LQR with
its 1 A limit) runs 1 s from an offset along x, two ways:

``magnet``
    the magnet starts displaced by the offset (the rest at the
    equilibrium), the estimator at the equilibrium (its prior: 1 mm
    standard deviation in position). The row ``true state`` feeds the LQR
    the simulator's own state (no estimator): the controller's own limit,
    which no filter can pass.
``estimate``
    the magnet starts at the equilibrium, the filter's prior is displaced
    by the offset (a wrong start, e.g. after a restart or a bad
    calibration): the controller first acts on the wrong estimate.

Converged: no crash, the controller still on, and over the last 0.2 s both
the magnet (RMS about the equilibrium) and the estimate (RMS error) are
within 0.1 mm on every axis.
The offsets are tried in increasing order; a filter's limit is the largest
offset below its first failure.

Usage::

    python benchmarks/estimator_excursions.py            # about 10 minutes
    python benchmarks/estimator_excursions.py --params maggy_v2 --what magnet
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import argparse  # noqa: E402

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from maglev_ros.control.closed_loop import make_closed_loop  # noqa: E402
from maglev_ros.estimation import EstimatorConfig  # noqa: E402
from maglev_ros.physics import linearize, make_model  # noqa: E402

OFFSETS_MM = {
    'magnet': (0.25, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.5),
    'estimate': (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0),
}
TOLERANCE = 1e-4  # m
FILTERS = ('kf', 'ekf', 'ukf', 'true state')


class TrueState:
    """Stands in for the estimator: the simulator's own state, no uncertainty."""

    def __init__(self, loop):
        self.sim = loop.simulator
        self.freeze = loop.estimator.freeze
        self.last_nis, self.last_dof = 0.0, 0
        self.status = loop.estimator.status

    def reset(self) -> None:
        """Nothing to forget."""

    def step(self, y, currents) -> np.ndarray:
        """Return the true state, 12-state."""
        return self.sim.state

    def state_std(self) -> np.ndarray:
        """Return zeros: no uncertainty."""
        return np.zeros(10)

    @property
    def state_covariance(self) -> np.ndarray:
        """Zeros (10, 10): no uncertainty."""
        return np.zeros((10, 10))


def converges(model, lin, kind, what, offset, duration, seed) -> tuple[bool, str]:
    """Run one loop, the magnet's or the estimate's x offset (m): (converged, what happened)."""
    config = EstimatorConfig(filter='kf' if kind == 'true state' else kind)
    loop = make_closed_loop(model, estimator=config, linear=lin, seed=seed)
    est = loop.estimator
    if kind == 'true state':
        loop.estimator = TrueState(loop)
    shifted = lin.x_eq.copy()
    shifted[0] += offset
    if what == 'estimate':  # the loop resets the estimator: to the displaced prior
        est.reset = lambda x0=None, est=est: type(est).reset(est, shifted)
    r = loop.run(duration, x0=shifted if what == 'magnet' else None)
    if r.crashed:
        return False, f'crashed ({r.reason})'
    if not loop.controller.active:  # it gave up (the magnet rests on an exact equilibrium)
        return False, f'controller off: {r.messages[-1] if r.messages else "inactive"}'
    tail = r.t >= duration - 0.2
    rms, _ = r.hold(duration - 0.2)
    est_rms = np.sqrt(np.mean((r.estimate[tail, :3] - r.x[tail, :3]) ** 2, axis=0))
    restarts = loop.estimator.status().restarts if kind != 'true state' else 0
    text = (
        f'hold {rms.max() * 1e6:.0f} um, estimate {est_rms.max() * 1e6:.0f} um, '
        f'{restarts} restarts'
    )
    return bool(rms.max() < TOLERANCE and est_rms.max() < TOLERANCE), text


def limits_of(what, params_list, offsets, duration, seed) -> tuple[dict, list]:
    """Largest converging offset (mm) and the first failing one, per (parameters, filter)."""
    kinds = FILTERS if what == 'magnet' else FILTERS[:3]
    limits, notes = {}, []
    jobs = [(p, k) for p in params_list for k in kinds]
    for params, kind in tqdm(jobs, desc=f'{what} offsets', unit='filter'):
        model = make_model(params)
        lin = linearize(model)
        best, failed = 0.0, None
        for mm in offsets:
            ok, text = converges(model, lin, kind, what, mm * 1e-3, duration, seed)
            notes.append(
                f'{what} {params} {kind.upper()} {mm:g} mm: {"ok" if ok else "FAILS"}: {text}'
            )
            if not ok:
                failed = mm
                break
            best = mm
        limits[(params, kind)] = (best, failed)
    return limits, notes


def main(argv=None) -> int:
    """Try the offsets and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--params', nargs='+', default=['maggy_v2', 'maggy_v4'])
    parser.add_argument('--what', nargs='+', choices=list(OFFSETS_MM), default=list(OFFSETS_MM))
    parser.add_argument('--duration', type=float, default=1.0, help='simulated s per run')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    if args.duration <= 0.3:
        parser.error(f'--duration must be above 0.3 s, got {args.duration}')
    tables = []
    for what in args.what:
        offsets = OFFSETS_MM[what]
        limits, notes = limits_of(what, args.params, offsets, args.duration, args.seed)
        print('\n'.join(notes))
        kinds = FILTERS if what == 'magnet' else FILTERS[:3]
        lines = [
            f'Initial x offset of the {what}: the largest from which the loop converges '
            f'({args.duration:g} s, within {TOLERANCE * 1e3:g} mm at the end; tried '
            f'{", ".join(f"{v:g}" for v in offsets)} mm).',
            '',
            '| parameters | '
            + ' | '.join(k.upper() if k != 'true state' else k for k in kinds)
            + ' |',
            '|---|' + '---|' * len(kinds),
        ]
        for params in args.params:
            cells = []
            for kind in kinds:
                best, failed = limits[(params, kind)]
                tail = f' (fails at {failed:g})' if failed is not None else ' (all tried)'
                cells.append(f'{best:g} mm{tail}')
            lines.append(f'| {params} | ' + ' | '.join(cells) + ' |')
        tables.append('\n'.join(lines))
    print()
    print('\n\n'.join(tables))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
