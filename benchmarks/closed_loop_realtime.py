"""The closed loop in real time at 5 kHz, composed: real-time factor, CPU and latency.

The set-up of ``closed_loop.launch.xml`` composed in one process: the
simulator (V2, magnet free at its equilibrium, coil dynamics, 0.1 mT noise,
0.098 mT steps, one sample of sensor delay) paced by the wall clock, the
estimator (KF) at 5 kHz and the LQR at ``--control-rate`` (default 1 kHz: one
estimate and one command per 1 ms burst of 5 samples), run for ``--seconds``
(default 20) of wall time, in two implementations, each in a child process:

``loop``
    this tree: :class:`~maglev_ros.loop.ControlLoop` on a
    :class:`~maglev_ros.loop.PacedSimulatedPlant`, as the loop node hosts it
    (:func:`~maglev_ros.loop.build_simulated_loop` with its defaults), direct
    calls, no ROS;
``baseline``
    the composed nodes of commit ``7d111a2`` (the last one before the loop
    ran the lab): simulator, estimator and controller on one executor, samples,
    estimates and commands handed over through the intra-process taps; its own
    ``benchmarks/closed_loop_realtime.py --only composed`` in a temporary
    ``git worktree`` of that commit (``PYTHONPATH`` set to it), or in
    ``--baseline PATH``.

Printed per implementation: the real-time factor (simulated s per wall s:
samples stepped, or the baseline's observed samples, over 5000/s), the hold
RMS and largest excursion of x, y, z - z_eq, the CPU of its process in % of
one core and per simulated second (CPU over the real-time factor: the cost of
a second of the loop, whatever share of the machine it got); for the loop also
the latency from each sample to the command that answers it (the command's
stamp is the sample's: latency = the wall time the command is written minus
the wall time the sample was due), median and p99.
The two run in alternating rounds (``--rounds``, default 3) so that both see
the machine's load alike; the ratio of the median real-time factors (loop over
baseline) is measured in the same run.

Usage::

    python benchmarks/closed_loop_realtime.py                 # 3 rounds of 20 s each
    python benchmarks/closed_loop_realtime.py --seconds 60 --control-rate 1000
    python benchmarks/closed_loop_realtime.py --only loop

Real time at 5 kHz on a loaded 2-core machine falls behind: both
implementations then slow down (the loop: one burst a read, the simulation
waits), which the real-time factor shows. Compare the two in one run.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RATE = 5000.0
BASELINE_COMMIT = '7d111a2'
REPO = Path(__file__).resolve().parents[1]


def loop_child(seconds: float, control_rate: float) -> int:
    """Run the composed loop for ``seconds`` of wall time; print its figures as JSON."""
    from maglev_ros.loop import SimulatedLoopSettings, build_simulated_loop
    from maglev_ros.physics import make_model
    from maglev_ros.physics.equilibria import find_equilibria

    s = SimulatedLoopSettings(control_rate=control_rate)  # the loop node's defaults
    loop, plant = build_simulated_loop(s, clock=time.perf_counter)
    z_eq = find_equilibria(make_model(s.params))[0].z
    written = []
    write = plant.write

    def timed_write(command, stamp_ns):
        # latency of the sample this command answers: now minus the time it was due
        written.append(time.perf_counter() - plant.start - stamp_ns * 1e-9)
        write(command, stamp_ns)

    plant.write = timed_write
    positions = []
    loop.observers.add(lambda sample: positions.append(sample.state[:3]), 5)
    import gc

    gc.freeze()
    cpu0, wall0 = time.process_time(), time.perf_counter()
    end = wall0 + seconds
    loop.run(10**9, stop=lambda: time.perf_counter() >= end)
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    err = np.array(positions) - np.array([0.0, 0.0, z_eq])
    lat = np.array(written)
    print(
        json.dumps(
            {
                'samples': int(plant.simulator.samples),
                'wall': wall,
                'cpu': cpu / wall,
                'rms': np.sqrt(np.mean(err**2, axis=0)).tolist(),
                'worst': np.abs(err).max(axis=0).tolist(),
                'crashed': bool(loop.stopped),
                'overruns': int(plant.overruns),
                'commands': int(lat.size),
                'latency_median': float(np.median(lat)),
                'latency_p99': float(np.percentile(lat, 99)),
            }
        )
    )
    return 0


def run_loop(seconds: float, control_rate: float) -> dict:
    """Run :func:`loop_child` in a child process of this tree; return its figures."""
    argv = [sys.executable, __file__, '--loop-child', '--seconds', str(seconds)]
    argv += ['--control-rate', str(control_rate)]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(argv, env=env, capture_output=True, text=True, check=False)
    if done.returncode:
        raise SystemExit(f'loop: failed:\n{done.stdout}{done.stderr}')
    r = json.loads(done.stdout.strip().splitlines()[-1])
    r['rtf'] = r['samples'] / RATE / r['wall']
    return r


def run_baseline(tree: Path, seconds: float, control_rate: float) -> dict:
    """Run the baseline tree's own benchmark, composed set-up; parse its figures."""
    argv = [sys.executable, str(tree / 'benchmarks' / 'closed_loop_realtime.py')]
    argv += ['--only', 'composed', '--seconds', str(seconds)]
    argv += ['--control-rate', str(control_rate)]
    env = dict(os.environ, PYTHONPATH=str(tree))
    done = subprocess.run(argv, env=env, capture_output=True, text=True, check=False)
    out = done.stdout
    m = re.search(
        r'composed: (\d+) samples in ([0-9.]+) s = ([0-9.]+) of real time; hold RMS x y z '
        r'(\S+) (\S+) (\S+) um, largest (\S+) (\S+) (\S+) um; crashed (\w+)',
        out,
    )
    cpu = re.search(r'total CPU ([0-9.]+) %', out)
    if done.returncode or m is None or cpu is None:
        raise SystemExit(f'baseline: failed:\n{out}{done.stderr}')
    return {
        'rtf': float(m.group(3)),
        'rms': [1e-6 * float(v) for v in m.group(4, 5, 6)],
        'worst': [1e-6 * float(v) for v in m.group(7, 8, 9)],
        'crashed': m.group(10) == 'True',
        'cpu': float(cpu.group(1)) / 100.0,
    }


def _print(label: str, r: dict) -> None:
    um = ' '.join(f'{1e6 * v:.1f}' for v in r['rms'])
    worst = ' '.join(f'{1e6 * v:.1f}' for v in r['worst'])
    line = (
        f'{label:<10}: real-time factor {r["rtf"]:.3f}; hold RMS x y z {um} um, largest '
        f'{worst} um; crashed {r["crashed"]}; CPU {100 * r["cpu"]:.1f} % of a core '
        f'({100 * r["cpu"] / max(r["rtf"], 1e-9):.1f} % per simulated second)'
    )
    if 'latency_median' in r:
        line += (
            f'; sample -> command latency median {1e3 * r["latency_median"]:.3f} ms, p99 '
            f'{1e3 * r["latency_p99"]:.3f} ms ({r["commands"]} commands, '
            f'{r["overruns"]} overruns)'
        )
    print(line, flush=True)


def main() -> int:
    """Run the implementations and print their figures."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=20.0, help='s of wall time each')
    ap.add_argument('--control-rate', type=float, default=1000.0, help='Hz (default 1000)')
    ap.add_argument('--only', choices=('loop', 'baseline'), help='one implementation only')
    ap.add_argument('--baseline', type=Path, help=f'a checkout of {BASELINE_COMMIT}')
    ap.add_argument('--rounds', type=int, default=3, help='alternating rounds (default 3)')
    ap.add_argument('--loop-child', action='store_true', help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.loop_child:
        return loop_child(args.seconds, args.control_rate)
    if not args.seconds > 0:
        print(f'closed_loop_realtime: error: --seconds must be > 0, got {args.seconds}')
        return 2
    print(f'load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs', flush=True)
    rtf: dict[str, list[float]] = {'loop': [], 'baseline': []}
    per: dict[str, list[float]] = {'loop': [], 'baseline': []}  # CPU per simulated s
    with tempfile.TemporaryDirectory() as tmp:
        tree = args.baseline
        if tree is None and args.only != 'loop':
            tree = Path(tmp) / 'baseline'
            subprocess.run(
                ['git', '-C', str(REPO), 'worktree', 'add', '--detach', str(tree),
                 BASELINE_COMMIT],
                check=True, capture_output=True,
            )  # fmt: skip
        try:
            for k in range(args.rounds):  # alternating: both see the machine's load alike
                for label in ('loop', 'baseline'):
                    if args.only not in (None, label):
                        continue
                    if label == 'loop':
                        r = run_loop(args.seconds, args.control_rate)
                    else:
                        r = run_baseline(tree, args.seconds, args.control_rate)
                    _print(f'{label} {k + 1}', r)
                    rtf[label].append(r['rtf'])
                    per[label].append(r['cpu'] / max(r['rtf'], 1e-9))
        finally:
            if args.baseline is None and tree is not None:
                subprocess.run(
                    ['git', '-C', str(REPO), 'worktree', 'remove', '--force', str(tree)],
                    check=False, capture_output=True,
                )  # fmt: skip
    print(f'load average {os.getloadavg()[0]:.2f} at the end', flush=True)
    if rtf['loop'] and rtf['baseline']:
        print(
            f'median real-time factor of the loop over the composed nodes (baseline, same '
            f'run, {args.rounds} alternating rounds): '
            f'{np.median(rtf["loop"]) / np.median(rtf["baseline"]):.2f}x '
            f'({np.median(rtf["loop"]):.3f} / {np.median(rtf["baseline"]):.3f}); CPU per '
            f'simulated second {np.median(per["loop"]) / np.median(per["baseline"]):.2f}x'
        )
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
