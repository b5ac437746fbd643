"""The composed control loop in real time: CPU, real-time factor and latency per filter.

What the loop node (``ros2 run maglev_ros loop``) runs, without ROS: the
simulator paced by the wall clock (5 kHz samples in 1 ms bursts), the
estimator on every sample and the LQR once per control period, through
:class:`maglev_ros.loop.ControlLoop`. For each filter it prints the loop's
CPU as a share of one core, the real-time factor, the overruns, and the
latency from a burst's due time (when its newest sample was taken) to the
write of the command answering it (median and p99). The baseline, measured
in the same run, is the same loop with the estimator and the controller
replaced by a zero command (the plant's own pacing and stepping): the
filters' cost is the difference.

Usage::

    python benchmarks/loop_realtime.py                  # kf ekf ukf, 10 s each
    python benchmarks/loop_realtime.py --seconds 20 --filters kf ukf
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from maglev_ros.loop import SimulatedLoopSettings, build_simulated_loop


class _ZeroController:
    """Commands zero: the baseline loop (the plant's pacing and stepping only)."""

    active = True
    reference = None

    def reset(self):
        pass

    def command(self, t, y=None, currents=None):
        return np.zeros(4)

    def status(self):
        from maglev_ros.control.safety import ControllerStatus

        return ControllerStatus('OK', '', True, 0, 0)


def measure(settings: SimulatedLoopSettings, seconds: float, baseline: bool = False) -> dict:
    loop, plant = build_simulated_loop(settings)
    latency = []
    write = plant.write

    def timed_write(command, stamp_ns):
        write(command, stamp_ns)
        due = plant.start + stamp_ns * 1e-9
        latency.append(time.monotonic() - due)

    plant.write = timed_write
    if baseline:
        loop.estimator, loop.controller, loop.pd = None, _ZeroController(), True
    samples = int(seconds * settings.sample_rate)
    cpu, wall = time.process_time(), time.monotonic()
    loop.run(samples)
    cpu, wall = time.process_time() - cpu, time.monotonic() - wall
    lat = np.array(latency[100:]) * 1e3
    return {
        'cpu': cpu / wall,
        'rtf': plant.real_time_factor,
        'overruns': plant.overruns,
        'lost': loop.stopped,
        'p50': float(np.median(lat)) if lat.size else float('nan'),
        'p99': float(np.percentile(lat, 99)) if lat.size else float('nan'),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--filters', nargs='+', default=['kf', 'ekf', 'ukf'])
    args = parser.parse_args()
    base = measure(SimulatedLoopSettings(), args.seconds, baseline=True)
    print(f'{args.seconds:g} s per run, 5000 Hz samples, LQR at 1000 Hz (V2, noise 0.1 mT)')
    print(f'{"loop":<22} {"CPU of a core":>13} {"RTF":>6} {"overruns":>8} '
          f'{"latency p50/p99 ms":>19} {"filter+LQR CPU":>15}')  # fmt: skip
    rows = [('plant only (baseline)', base)]
    for name in args.filters:
        rows.append((f'{name} + LQR', measure(SimulatedLoopSettings(filter=name), args.seconds)))
    for name, r in rows:
        extra = r['cpu'] - base['cpu']
        print(
            f'{name:<22} {r["cpu"]:>12.1%} {r["rtf"]:>6.3f} {r["overruns"]:>8d} '
            f'{r["p50"]:>9.2f}/{r["p99"]:<9.2f} {extra:>14.1%}'
            + ('  magnet lost' if r['lost'] else '')
        )


if __name__ == '__main__':
    main()
