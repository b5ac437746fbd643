"""Consistency of the KF, EKF and UKF in the closed loop: average NEES and NIS, 95 % bounds.

For each parameter set and filter: 10 s of levitation in the simulator with
the lab's noise (0.1 mT, quantisation 0.098 mT, one sample of sensor delay,
coil dynamics) and the LQR in the loop
(:func:`maglev_ros.estimation.consistency.run_consistency`), the first 0.5 s
left out. The filter starts at the true state with its steady-state
covariance (``--start steady``, default) or with its configured prior
(``--start prior``: the prior's slow transient, seconds long with a small
process noise, then weighs in the average).

Bounds: the NIS's over every sample (a consistent filter's innovations are
white); the NEES's over the *effective* sample count, the samples divided by
the NEES series' integrated autocorrelation time
(:func:`~maglev_ros.estimation.consistency.correlation_time`): the errors
of consecutive samples are correlated over hundreds of samples, and the mean
of correlated samples varies as much as that of fewer independent ones.

Tunings:

``matched``
    the process noise that stands for each filter's own prediction error on
    each parameter set (the simulated plant has no random disturbance: the
    filter's "process noise" is its model error, the coil current's ramp
    inside a sample, the KF's linearisation); see
    :data:`~maglev_ros.estimation.consistency.MATCHED_NOISE`.
``default``
    :class:`~maglev_ros.estimation.EstimatorConfig`'s process noise, sized
    for a model that is off by +-10 % (polarisation, mass; see
    ``angular_acceleration_noise``): conservative on the exact plant.
``none``
    no process noise beyond 0.1 mA of current: overconfident.

Usage::

    python benchmarks/estimator_consistency.py              # 5-15 minutes
    python benchmarks/estimator_consistency.py --duration 3 --params maggy_v2 --tunings matched
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import argparse  # noqa: E402
import dataclasses  # noqa: E402

from tqdm import tqdm  # noqa: E402

from maglev_ros.estimation import EstimatorConfig  # noqa: E402
from maglev_ros.estimation.consistency import (  # noqa: E402
    MATCHED_NOISE,
    ConsistencyResult,
    matched_config,
    run_consistency,
)
from maglev_ros.physics import linearize, make_model  # noqa: E402

TUNINGS = ('matched', 'default', 'none')


def tuning(name: str, params: str, kind: str) -> EstimatorConfig:
    """Return the filter ``kind`` with tuning ``name`` for ``params``."""
    if name == 'matched':
        return matched_config(params, kind)
    config = EstimatorConfig(filter=kind)
    if name == 'none':
        return dataclasses.replace(
            config,
            current_noise=1e-4,
            acceleration_noise=0.0,
            vertical_acceleration_noise=0.0,
            angular_acceleration_noise=0.0,
        )
    return config


def main(argv=None) -> int:
    """Run the loops and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=10.0, help='simulated s per run')
    parser.add_argument('--params', nargs='+', default=['maggy_v2', 'maggy_v4'])
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--tunings', nargs='+', default=list(TUNINGS), choices=TUNINGS)
    parser.add_argument(
        '--start',
        default='steady',
        choices=('steady', 'prior'),
        help='the covariance the filter starts from (see run_consistency)',
    )
    args = parser.parse_args(argv)
    unknown = [p for p in args.params if p not in {k[0] for k in MATCHED_NOISE}]
    if unknown and 'matched' in args.tunings:
        parser.error(f'no matched tuning for {", ".join(unknown)}: use --tunings default none')
    if args.duration <= 1.0:
        parser.error(
            f'--duration must exceed the 0.5 s settling time by 0.5 s, got {args.duration}'
        )
    runs = [(p, t, f) for p in args.params for t in args.tunings for f in ('kf', 'ekf', 'ukf')]
    rows = []
    models = {}
    for params, name, kind in tqdm(runs, desc='closed loops', unit='run'):
        if params not in models:
            model = make_model(params)
            models[params] = (model, linearize(model))
        model, lin = models[params]
        config = tuning(name, params, kind)
        r = run_consistency(
            model, config, args.duration, seed=args.seed, linear=lin, start=args.start
        )
        rows.append((params, name, r))
    lines = [
        f'{args.duration:g} s of levitation per run (first 0.5 s left out), seed {args.seed}, '
        f'filters started from the {args.start} covariance.',
        '',
        '| parameters | tuning | filter | average NEES (n = 10) | correlation (samples) '
        '| 95 % band | NEES | average NIS | 95 % band | NIS '
        '| e^2/P per state (x y z a b vx vy vz wx wy) |',
        '|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for params, name, r in rows:
        crash = ' (CRASHED)' if r.crashed else ''
        lines.append(
            f'| {params} | {name} | {r.filter.upper()}{crash} | {r.nees:.2f} '
            f'| {r.nees_correlation:.0f} | {r.nees_band[0]:.2f} - {r.nees_band[1]:.2f} '
            f'| {ConsistencyResult.verdict(r.nees, r.nees_band)} '
            f'| {r.nis:.3f} (dof {r.nis_dof:.2f}) | {r.nis_band[0]:.3f} - {r.nis_band[1]:.3f} '
            f'| {ConsistencyResult.verdict(r.nis, r.nis_band)} '
            f'| {" ".join(f"{v:.2f}" for v in r.nees_states)} |'
        )
    print('\n'.join(lines))
    matched = [r for _, name, r in rows if name == 'matched']
    if matched:
        ok = all(r.nees_ok and r.nis_ok and not r.crashed for r in matched)
        print()
        print(
            f'{"ok" if ok else "NOT MET":8s}matched tuning: every average NEES and NIS in its band'
        )
        return 0 if ok else 1
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
