"""How much command latency the real-time loop tolerates, per LQR design (ROS-free).

The real-time pattern of ``closed_loop.launch.xml separate:=true`` in simulation:
the KF at 5 kHz on the noisy, delayed sensors of ``make_closed_loop`` (V2, coil
dynamics, 0.1 mT noise, 0.098 mT steps), the LQR at 1 kHz on every fifth estimate.
Each estimate reaches the controller late, and the controller answers the newest
one that has arrived (as its keep-last-1 subscription does); its command reaches
the plant ``--after`` ms later (at least one sample) and is held until the next.
The latency from an estimate to its command's first sample is

* ``'4'``: a fixed 4 ms;
* ``'r2.7/6.9'``: random per estimate, lognormal with median 2.7 ms and 90th
  percentile 6.9 ms, in order;
* ``'s3/20'``: 2 ms, and stalls of everything before the controller at random
  moments, 3 a second, 20 ms each (a process that waits for a core): the estimates
  of a stall arrive at its end.

For each design (``command_delay`` N: the LQR designed for N ms of latency) and
latency it prints whether the magnet was lost (and when) and the hold
RMS and largest excursion of x, y, z - z_eq over the last two thirds of the run,
from the magnet at rest at the equilibrium; per latency the first design is the
baseline the others' x/y RMS is a ratio of.

Usage::

    python benchmarks/latency_tolerance.py                 # the table of docs/benchmarks.md
    python benchmarks/latency_tolerance.py --seconds 10 --designs 3 5 --latencies 4 s3/20
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

RATE = 5000  # samples per second
EVERY = 5  # samples per command (1 kHz)


def parse_latency(text: str):
    """``'4'``: fixed ms; ``'r2.7/6.9'``: lognormal median/p90 ms; ``'s3/20'``: stalls."""
    if text[:1] in ('r', 's'):
        a, b = (float(v) for v in text[1:].split('/'))
        if text[0] == 'r' and not 0 < a < b:
            raise ValueError(f'latency {text!r}: need 0 < median < p90')
        if text[0] == 's' and not (a > 0 and b > 0):
            raise ValueError(f'latency {text!r}: need stalls per s > 0 and ms > 0')
        return ('random' if text[0] == 'r' else 'stalls', a, b)
    value = float(text)
    if not value >= 0:
        raise ValueError(f'latency {text!r}: need >= 0 ms')
    return ('fixed', value, value)


STALL_BASE_MS = 2.0  # latency outside the stalls


def run(
    design: int,
    latency,
    seconds: float,
    seed: int = 1,
    after: float = 1.0,
) -> dict:
    """Run the loop once; return crash time (or None), RMS and largest excursion, m.

    ``after`` ms of each latency (at least one sample) lie after the
    controller; the rest is the estimate's way to it.
    """
    from maglev_ros.control import ControllerConfig, LqrController
    from maglev_ros.control.closed_loop import make_closed_loop
    from maglev_ros.physics import make_model
    from maglev_ros.physics.kernels import odometry_round_trip

    loop = make_closed_loop(seed=seed)
    sim, est = loop.simulator, loop.estimator
    config = ControllerConfig(sample_rate=RATE / EVERY, command_delay=design, input_timeout=0.05)
    ctrl = LqrController(make_model('maggy_v2'), config)
    rng = np.random.default_rng(seed)
    kind, a, b = latency
    sigma = np.log(b / a) / 1.2816 if kind == 'random' else 0.0
    tail = max(1, round(after * RATE / 1000))  # samples after the controller

    def late() -> int:  # samples from the estimate to the command's first sample
        if kind == 'random':
            ms = a * np.exp(sigma * rng.standard_normal())
        else:
            ms = a if kind == 'fixed' else STALL_BASE_MS
        return max(1, round(ms * RATE / 1000))

    n = round(seconds * RATE)
    y = sim.reset(None)
    est.reset()
    ctrl.reset()
    applied = np.zeros(4)
    arriving: list[tuple[int, int, np.ndarray]] = []  # (sample it arrives, its sample, state)
    queue: list[tuple[int, np.ndarray]] = []  # (first sample it drives, command)
    stalled_until = -1
    pos = np.zeros((n, 3))
    crash = None
    for k in range(n):
        x = est.step(y, sim.currents)
        if kind == 'stalls' and rng.random() < a / RATE:
            stalled_until = max(stalled_until, k + round(b * RATE / 1000))
        if k % EVERY == EVERY - 1:
            arrive = max(k + late() - tail, stalled_until, arriving[-1][0] if arriving else 0)
            arriving.append((arrive, k, odometry_round_trip(np.asarray(x))))
        newest = None
        while arriving and arriving[0][0] <= k:  # keep-last-1: the newest arrived one
            newest = arriving.pop(0)[1:]
        if newest is not None:
            queue.append((k + tail, ctrl.command(newest[0] / RATE, newest[1])))
        while queue and queue[0][0] <= k:
            applied = queue.pop(0)[1]
        y = sim.step(applied)
        if sim.crashed:
            crash = k / RATE
            pos = pos[:k]
            break
        pos[k] = sim.state[:3]
    pos[:, 2] -= loop.z_eq
    tail_pos = pos[len(pos) // 3 :]
    return {
        'crash': crash,
        'rms': np.sqrt(np.mean(tail_pos**2, axis=0)),
        'worst': np.max(np.abs(tail_pos), axis=0),
    }


def main() -> int:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=5.0, help='s simulated per run')
    ap.add_argument('--designs', type=int, nargs='+', default=[5, 1, 3], help='command_delay')
    ap.add_argument(
        '--latencies',
        nargs='+',
        default=['1', '4', '6', 'r2.7/6.9', 's3/10', 's3/20'],
        help='ms: a number (fixed), rMEDIAN/P90 (lognormal) or sRATE/MS (stalls)',
    )
    ap.add_argument('--after', type=float, default=1.0, help='ms of latency after the controller')
    ap.add_argument('--seed', type=int, default=1)
    args = ap.parse_args()
    try:
        latencies = [(text, parse_latency(text)) for text in args.latencies]
        for d in args.designs:
            if not 0 <= d <= 20:
                raise ValueError(f'--designs: command_delay from 0 to 20, got {d}')
        if not args.seconds > 0:
            raise ValueError(f'--seconds must be > 0, got {args.seconds}')
        if not args.after >= 0:
            raise ValueError(f'--after must be >= 0 ms, got {args.after}')
    except ValueError as err:
        print(f'latency_tolerance: error: {err}', file=sys.stderr)
        return 2
    print(f'{"latency":>9} {"design":>7}  outcome (RMS and largest of x y z - z_eq, um)')
    for text, latency in latencies:
        base = None
        for design in args.designs:
            r = run(design, latency, args.seconds, args.seed, args.after)
            rms = ' '.join(f'{1e6 * v:.0f}' for v in r['rms'])
            worst = ' '.join(f'{1e6 * v:.0f}' for v in r['worst'])
            if r['crash'] is not None:
                outcome = f'lost at {r["crash"]:.2f} s'
            else:
                outcome = f'held {args.seconds:g} s: RMS {rms}, largest {worst}'
                if base is None:
                    base = r['rms'][:2]
                else:
                    ratio = np.mean(r['rms'][:2]) / np.mean(base)
                    outcome += f' (x/y RMS x{ratio:.2f} of the first held)'
            print(f'{text:>9} {design:>4} ms  {outcome}', flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
