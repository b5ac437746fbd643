"""Consistency of the KF, EKF and UKF in the closed loop: average NEES and NIS, 95 % bounds.

For each parameter set and filter: 10 s of levitation in the simulator with
the lab's noise (0.1 mT, quantisation 0.098 mT, one sample of sensor delay,
coil dynamics) and the LQR in the loop
(:func:`maglev_ros.estimation.consistency.run_consistency`), the first 0.5 s
left out. Three tunings:

``default``
    :class:`~maglev_ros.estimation.EstimatorConfig`'s process noise, sized
    for a model that is off by +-10 % (polarisation, mass; see
    ``angular_acceleration_noise``).
``low``
    a small process noise for the exact plant: ``current_noise`` 0.3 mA,
    ``acceleration_noise`` 0.01 m/s^2, ``angular_acceleration_noise`` 0.5
    rad/s^2 (the KF's average NEES on V2 is near 10 with it).
``none``
    no process noise beyond 0.1 mA of current: the model is the plant.

Usage::

    python benchmarks/estimator_consistency.py              # 4-10 minutes
    python benchmarks/estimator_consistency.py --duration 3 --params maggy_v2
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import argparse  # noqa: E402
import dataclasses  # noqa: E402

from tqdm import tqdm  # noqa: E402

from maglev_ros.estimation import EstimatorConfig  # noqa: E402
from maglev_ros.estimation.consistency import ConsistencyResult, run_consistency  # noqa: E402
from maglev_ros.physics import linearize, make_model  # noqa: E402

TUNINGS = {
    'default': {},
    'low': {
        'current_noise': 3e-4,
        'acceleration_noise': 0.01,
        'angular_acceleration_noise': 0.5,
    },
    'none': {'current_noise': 1e-4, 'acceleration_noise': 0.0, 'angular_acceleration_noise': 0.0},
}


def main(argv=None) -> int:
    """Run the loops and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=10.0, help='simulated s per run')
    parser.add_argument('--params', nargs='+', default=['maggy_v2', 'maggy_v4'])
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    if args.duration <= 1.0:
        parser.error(
            f'--duration must exceed the 0.5 s settling time by 0.5 s, got {args.duration}'
        )
    runs = [(p, t, f) for p in args.params for t in TUNINGS for f in ('kf', 'ekf', 'ukf')]
    rows = []
    models = {}
    for params, tuning, kind in tqdm(runs, desc='closed loops', unit='run'):
        if params not in models:
            model = make_model(params)
            models[params] = (model, linearize(model))
        model, lin = models[params]
        config = dataclasses.replace(EstimatorConfig(filter=kind), **TUNINGS[tuning])
        r = run_consistency(model, config, args.duration, seed=args.seed, linear=lin)
        rows.append((params, tuning, r))
    lines = [
        f'{args.duration:g} s of levitation per run (first 0.5 s left out), seed {args.seed}.',
        '',
        '| parameters | tuning | filter | average NEES (n = 10) | 95 % band | NEES | '
        'average NIS | 95 % band | NIS | e^2/P per state (x y z a b vx vy vz wx wy) |',
        '|---|---|---|---|---|---|---|---|---|---|',
    ]
    for params, tuning, r in rows:
        crash = ' (CRASHED)' if r.crashed else ''
        lines.append(
            f'| {params} | {tuning} | {r.filter.upper()}{crash} | {r.nees:.2f} '
            f'| {r.nees_band[0]:.2f} - {r.nees_band[1]:.2f} '
            f'| {ConsistencyResult.verdict(r.nees, r.nees_band)} '
            f'| {r.nis:.3f} (dof {r.nis_dof:.2f}) | {r.nis_band[0]:.3f} - {r.nis_band[1]:.3f} '
            f'| {ConsistencyResult.verdict(r.nis, r.nis_band)} '
            f'| {" ".join(f"{v:.2f}" for v in r.nees_states)} |'
        )
    print('\n'.join(lines))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
