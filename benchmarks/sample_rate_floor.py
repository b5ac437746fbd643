"""How the closed loop holds as the sample rate falls: the estimator's noise floor.

Separate processes exchange every sample through the middleware, so they run at a
lower sample rate than the board's 5 kHz. This script measures, without any
middleware, what that rate alone costs: the ROS-free closed loop (V2, KF + LQR,
0.1 mT noise, 0.098 mT steps, one sample of sensor delay, coil dynamics), the
estimator and the LQR designed for the rate and for ``--delay`` periods of command
latency, for each rate and seed. Baseline in the same run: the board's 5 kHz.

Printed per rate: the hold RMS and the largest excursion of x and y after 1 s, the
position estimate's RMS error, and how many runs lost the magnet (and when).

With ``--average N`` the same loop runs with averaged samples too, in the same run:
the simulator at N times each ``--average-rates`` rate, each sample the mean of its
N readings (and currents), the KF modelling the mean over the group
(``EstimatorConfig.average``), for each command delay of ``--delays`` and each
``--offsets`` (readings of a group that still hold the previous command: where a
command lands in a real-time group of separate processes).

    python benchmarks/sample_rate_floor.py --rates 1000 2500 5000 --seeds 4 --seconds 20
    python benchmarks/sample_rate_floor.py --rates 1000 5000 --average 5 --delays 2 3 \
        --offsets 0 2 4 --seeds 4 --seconds 20
"""

from __future__ import annotations

import argparse

import numpy as np
from tqdm import tqdm

from maglev_ros.control import ControllerConfig
from maglev_ros.control.closed_loop import ClosedLoop, make_closed_loop
from maglev_ros.estimation import EstimatorConfig


def hold(
    rate: float,
    seed: int,
    delay: int,
    seconds: float,
    average: int = 1,
    offset: int = 0,
    scale: float = 1.0,
    extra: int = 0,
    modelled: bool = True,
) -> dict:
    """Run the loop at ``rate`` Hz for ``seconds`` s; return its hold figures.

    ``average`` readings per sample (at ``average`` x ``rate``), a new command
    from reading ``offset`` of its group on; the estimator's disturbances
    (held over a sample) times ``scale``; the commands applied ``extra``
    periods later than the LQR designs for. Not ``modelled``: the estimator
    reads each mean as one reading (of its sample's instant) with the mean's noise.
    """
    c = EstimatorConfig()
    told = average if modelled else 1
    noise = 1.0 if modelled else average**-0.5
    loop = make_closed_loop(
        'maggy_v2',
        estimator=EstimatorConfig(
            sample_rate=rate,
            bias_states=True,
            average=told,
            sensor_noise=c.sensor_noise * noise,
            quantization=c.quantization * noise,
            acceleration_noise=c.acceleration_noise * scale,
            angular_acceleration_noise=c.angular_acceleration_noise * scale,
            current_noise=c.current_noise * scale,
        ),
        controller=ControllerConfig(sample_rate=rate, command_delay=delay),
        seed=seed,
        average=average,
        offset=offset,
    )
    if extra:
        loop = ClosedLoop(loop.simulator, loop.estimator, loop.controller, delay + extra,
                          average, offset)  # fmt: skip
    r = loop.run(seconds)
    start = int(rate)  # after 1 s
    x = np.asarray(r.x)[start:, :2]
    error = (np.asarray(r.estimate) - np.asarray(r.x))[start:, :2]
    lost = bool(r.crashed)
    return {
        'lost_at': len(r.x) / rate if lost else None,
        'rms': np.sqrt(np.mean(x**2, axis=0)) if len(x) else np.full(2, np.nan),
        'largest': np.abs(x).max(axis=0) if len(x) else np.full(2, np.nan),
        'error': np.sqrt(np.mean(error**2, axis=0)) if len(x) else np.full(2, np.nan),
    }


def _figure(kept: list[dict], key: str, pick) -> str:
    """Return ``pick`` over the kept runs of figure ``key``, um, as 'x, y' ('-': none)."""
    if not kept:
        return '-'
    v = pick(np.array([r[key] for r in kept]), axis=0) * 1e6
    return f'{v[0]:.0f}, {v[1]:.0f}'


def _row(label: str, runs: list[dict]) -> str:
    """One printed row: the lost count, the kept runs' figures, the lost runs' times."""
    kept = [r for r in runs if r['lost_at'] is None]
    lost = [f'{r["lost_at"]:.2f}' for r in runs if r['lost_at'] is not None]
    return (
        f'{label}  {len(lost):>3} of {len(runs)}  {_figure(kept, "rms", np.median):>14}  '
        f'{_figure(kept, "largest", np.max):>16}  {_figure(kept, "error", np.median):>23}  '
        f'{" ".join(lost) or "-"}'
    )


def main() -> None:
    """Print the hold per sample rate (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--rates', type=float, nargs='+', default=[1000.0, 2500.0, 5000.0])
    p.add_argument('--seeds', type=int, default=4, help='seeds 0 .. N-1 per rate')
    p.add_argument('--delays', type=int, nargs='+', default=[2], help='command latency, periods')
    p.add_argument('--seconds', type=float, default=20.0)
    p.add_argument('--average', type=int, default=1, help='readings per averaged sample')
    p.add_argument('--average-rates', type=float, nargs='+', default=[1000.0])
    p.add_argument('--offsets', type=int, nargs='+', default=[0], help='readings before a command')
    p.add_argument('--scaled', action='store_true',
                   help='averaged rows also with disturbances scaled for the rate')  # fmt: skip
    p.add_argument('--extra', type=int, nargs='+', default=[0],
                   help='averaged rows: periods of latency beyond the design')  # fmt: skip
    p.add_argument('--unmodelled', action='store_true',
                   help='averaged rows also with the means read as single readings')  # fmt: skip
    args = p.parse_args()
    print(f'{"rate Hz":>8}  {"sensed Hz":>9}  {"model":>6}  {"delay":>5}  {"offset":>6}  '
          f'{"Q scale":>7}  {"extra":>5}  {"lost":>7}  {"RMS x, y um":>14}  '
          f'{"largest x, y um":>16}  {"estimate error x, y um":>23}  lost at (s)')  # fmt: skip
    rows = [(rate, 1, d, 0, 1.0, 0, True) for rate in args.rates for d in args.delays]
    if args.average > 1:
        # the disturbances held over a sample keep their intensity: std x sqrt(Ts / Ts_sensed)
        scales = [1.0, args.average**-0.5] if args.scaled else [1.0]
        models = [True, False] if args.unmodelled else [True]
        rows += [(rate, args.average, d, o, q, e, m) for rate in args.average_rates
                 for m in models for q in scales for d in args.delays for o in args.offsets
                 for e in args.extra]  # fmt: skip
    for rate, average, delay, offset, scale, extra, modelled in tqdm(rows, leave=False):
        runs = [hold(rate, seed, delay, args.seconds, average, offset, scale, extra, modelled)
                for seed in range(args.seeds)]  # fmt: skip
        model = 'mean' if average > 1 and modelled else 'single'
        label = f'{rate:>8.0f}  {rate * average:>9.0f}  {model:>6}  {delay:>5}  '
        label += f'{offset if average > 1 else "-":>6}  {scale:>7.2f}  {extra:>5}'
        tqdm.write(_row(label, runs))


if __name__ == '__main__':
    main()
