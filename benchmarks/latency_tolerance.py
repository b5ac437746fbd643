"""How much command latency the real-time loop tolerates, per LQR design (ROS-free).

The real-time pattern of ``closed_loop.launch.xml`` in simulation: the KF at
5 kHz on the noisy, delayed sensors of ``make_closed_loop`` (V2, coil
dynamics, 0.1 mT noise, 0.098 mT steps), the LQR at 1 kHz on every fifth
estimate, its command reaching the plant ``latency`` later (a fixed time, or
random: lognormal, median and 90th percentile given, the shape of what the
launch file's processes measured), in order, held until the next one. For
each design (``command_delay`` N: the LQR designed for N ms of latency) and
latency it prints whether the magnet was lost (and when) and the hold RMS and
largest excursion of x, y, z - z_eq over the last two thirds of the run,
from the magnet at rest at the equilibrium.

Usage::

    python benchmarks/latency_tolerance.py                 # the table of docs/benchmarks.md
    python benchmarks/latency_tolerance.py --seconds 10 --designs 1 3 --latencies 2 4 r1.8/4.6
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

RATE = 5000  # samples per second
EVERY = 5  # samples per command (1 kHz)


def parse_latency(text: str):
    """``'4'``: a fixed 4 ms; ``'r1.8/4.6'``: lognormal, median 1.8 ms, p90 4.6 ms."""
    if text.startswith('r'):
        median, p90 = (float(v) for v in text[1:].split('/'))
        if not 0 < median < p90:
            raise ValueError(f'latency {text!r}: need 0 < median < p90')
        return ('random', median, p90)
    value = float(text)
    if not value >= 0:
        raise ValueError(f'latency {text!r}: need >= 0 ms')
    return ('fixed', value, value)


def run(design: int, latency, seconds: float, seed: int = 1) -> dict:
    """Run the loop once; return crash time (or None), RMS and largest excursion, m."""
    from maglev_ros.control import ControllerConfig, LqrController
    from maglev_ros.control.closed_loop import make_closed_loop
    from maglev_ros.physics import make_model
    from maglev_ros.physics.kernels import odometry_round_trip

    loop = make_closed_loop(seed=seed)
    sim, est = loop.simulator, loop.estimator
    ctrl = LqrController(
        make_model('maggy_v2'),
        ControllerConfig(sample_rate=RATE / EVERY, command_delay=design, input_timeout=0.05),
    )
    rng = np.random.default_rng(seed)
    kind, median, p90 = latency
    sigma = np.log(p90 / median) / 1.2816 if kind == 'random' else 0.0

    def late() -> int:  # samples from the estimate to the command's first sample
        ms = median * np.exp(sigma * rng.standard_normal()) if sigma else median
        return max(1, round(ms * RATE / 1000))

    n = round(seconds * RATE)
    y = sim.reset(None)
    est.reset()
    ctrl.reset()
    applied = np.zeros(4)
    queue: list[tuple[int, np.ndarray]] = []
    pos = np.zeros((n, 3))
    crash = None
    for k in range(n):
        x = est.step(y, sim.currents)
        if k % EVERY == EVERY - 1:
            command = ctrl.command(k / RATE, odometry_round_trip(np.asarray(x)))
            at = max(k + late(), queue[-1][0] if queue else 0)  # in order
            queue.append((at, command))
        while queue and queue[0][0] <= k:
            applied = queue.pop(0)[1]
        y = sim.step(applied)
        if sim.crashed:
            crash = k / RATE
            pos = pos[:k]
            break
        pos[k] = sim.state[:3]
    pos[:, 2] -= loop.z_eq
    tail = pos[len(pos) // 3 :]
    return {
        'crash': crash,
        'rms': np.sqrt(np.mean(tail**2, axis=0)),
        'worst': np.max(np.abs(tail), axis=0),
    }


def main() -> int:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=5.0, help='s simulated per run')
    ap.add_argument('--designs', type=int, nargs='+', default=[1, 3, 5], help='command_delay')
    ap.add_argument(
        '--latencies',
        nargs='+',
        default=['1', '4', '6', '8', 'r1.8/4.6', 'r2.7/6.9'],
        help='ms: a number (fixed) or rMEDIAN/P90 (lognormal)',
    )
    args = ap.parse_args()
    try:
        latencies = [(text, parse_latency(text)) for text in args.latencies]
        if not args.seconds > 0:
            raise ValueError(f'--seconds must be > 0, got {args.seconds}')
        for d in args.designs:
            if not 0 <= d <= 20:
                raise ValueError(f'--designs: command_delay from 0 to 20, got {d}')
    except ValueError as err:
        print(f'latency_tolerance: error: {err}', file=sys.stderr)
        return 2
    print(f'{"design":>8} {"latency ms":>11}  outcome (RMS and largest of x y z - z_eq, um)')
    for design in args.designs:
        for text, latency in latencies:
            r = run(design, latency, args.seconds)
            rms = ' '.join(f'{1e6 * v:.0f}' for v in r['rms'])
            worst = ' '.join(f'{1e6 * v:.0f}' for v in r['worst'])
            outcome = (
                f'lost at {r["crash"]:.2f} s'
                if r['crash'] is not None
                else f'held {args.seconds:g} s: RMS {rms}, largest {worst}'
            )
            print(f'{design:>5} ms {text:>11}  {outcome}', flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
