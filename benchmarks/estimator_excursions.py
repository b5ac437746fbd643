"""Large excursions: from which initial x offset each filter still brings the magnet back.

For each parameter set and filter (KF, EKF, UKF; defaults), the closed loop
of ``make_closed_loop`` (lab noise, sensor delay, coil dynamics, the LQR)
starts with the magnet displaced along x by the offset (the rest of the state
at the equilibrium) while the estimator starts at the equilibrium (its prior:
1 mm standard deviation in position). Converged: no crash, and over the last
0.2 s of the run both the magnet (RMS about the equilibrium) and the
estimate (RMS error) are within 0.1 mm on every axis. The offsets are tried
in increasing order; a filter's limit is the largest offset below its first
failure. The row ``true state`` feeds the LQR the simulator's own state
(no estimator): the controller's limit, which no filter can pass.

Usage::

    python benchmarks/estimator_excursions.py            # a few minutes
    python benchmarks/estimator_excursions.py --params maggy_v2 --offsets 1 2 3
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

OFFSETS_MM = (0.25, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.5, 2.0, 3.0)
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


def converges(model, lin, kind, offset, duration, seed) -> tuple[bool, str]:
    """Run one loop from an x offset (m); return (converged, what happened)."""
    config = EstimatorConfig(filter='kf' if kind == 'true state' else kind)
    loop = make_closed_loop(model, estimator=config, linear=lin, seed=seed)
    if kind == 'true state':
        loop.estimator = TrueState(loop)
    x0 = lin.x_eq.copy()
    x0[0] += offset
    r = loop.run(duration, x0=x0)
    if r.crashed:
        return False, f'crashed ({r.reason})'
    tail = r.t >= duration - 0.2
    rms, _ = r.hold(duration - 0.2)
    est_rms = np.sqrt(np.mean((r.estimate[tail, :3] - r.x[tail, :3]) ** 2, axis=0))
    restarts = loop.estimator.status().restarts if kind != 'true state' else 0
    text = (
        f'hold {rms.max() * 1e6:.0f} um, estimate {est_rms.max() * 1e6:.0f} um, '
        f'{restarts} restarts'
    )
    return bool(rms.max() < TOLERANCE and est_rms.max() < TOLERANCE), text


def main(argv=None) -> int:
    """Try the offsets and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--params', nargs='+', default=['maggy_v2', 'maggy_v4'])
    parser.add_argument('--offsets', nargs='+', type=float, default=OFFSETS_MM, help='mm')
    parser.add_argument('--duration', type=float, default=1.0, help='simulated s per run')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    offsets = sorted(args.offsets)
    if offsets[0] <= 0 or args.duration <= 0.3:
        parser.error('offsets must be positive (mm) and --duration above 0.3 s')
    limits = {}
    notes = []
    jobs = [(p, k) for p in args.params for k in FILTERS]
    for params, kind in tqdm(jobs, desc='parameter sets x filters', unit='filter'):
        model = make_model(params)
        lin = linearize(model)
        best = 0.0
        for mm in offsets:
            ok, text = converges(model, lin, kind, mm * 1e-3, args.duration, args.seed)
            notes.append(f'{params} {kind.upper()} {mm:g} mm: {"ok" if ok else "FAILS"}: {text}')
            if not ok:
                break
            best = mm
        limits[(params, kind)] = (best, None if best == offsets[-1] else mm)
    print('\n'.join(notes))
    print()
    print(
        f'Largest initial x offset from which the loop converges ({args.duration:g} s runs, '
        f'within {TOLERANCE * 1e3:g} mm at the end), offsets tried: '
        f'{", ".join(f"{v:g}" for v in offsets)} mm.'
    )
    print()
    print('| parameters | ' + ' | '.join(k.upper() for k in FILTERS) + ' |')
    print('|---|' + '---|' * len(FILTERS))
    for params in args.params:
        cells = []
        for kind in FILTERS:
            best, first_fail = limits[(params, kind)]
            fail = f' (fails at {first_fail:g})' if first_fail is not None else ' (all)'
            cells.append(f'{best:g} mm{fail}')
        print(f'| {params} | ' + ' | '.join(cells) + ' |')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
