"""The estimator node at 5 kHz: CPU and lag, sample streams on the executor or in their thread.

Issue 9's real-time point needs an estimator process that keeps up with
5000 samples a second (the field of each of three sensors and the currents:
20 000 messages a second). This script runs the simulator (``mode:
realtime``, V2, magnet fixed at its equilibrium, coil dynamics, 0.1 mT noise,
one sample of sensor delay) and the estimator (KF, ``publish_rate`` 1000 Hz)
as two processes, as ``ros2 run`` starts them, and measures over
``--seconds`` of wall time after a warm-up:

- the CPU of each process (``/proc``, % of one core);
- the estimates received (an observer in this script, 1000 a second when the
  estimator keeps up) as a fraction of the samples the simulator produced;
- the estimate's lag: arrival time minus stamp, less its smallest value in
  the run (so 0 is the best the run saw), median and 99th percentile, ms.

Two variants, alternated ``--repeats`` times in the same run: the baseline
``stream_thread:=false`` (one EventsExecutor callback per message) and
``stream_thread:=true`` (:mod:`maglev_ros.nodes.sample_streams`). Printed:
each run, then the medians and the baseline's CPU over the streams' CPU.

    python benchmarks/estimator_node.py                 # 10 s per run, 2 repeats
    python benchmarks/estimator_node.py --seconds 20 --repeats 3

Run it on a quiet machine: both processes need most of a core each.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from process_cpu import Processes, benchmark_environment, cpu_seconds

RATE = 5000.0
DOMAIN = 76
_SIM = (
    'mode:=realtime magnet:=fixed coil_dynamics:=true sensor_delay:=1 '
    'sensor_noise:=0.0001 sensor_quantization:=0.000098'
).split()
_EST = 'sensor_noise:=0.0001 quantization:=0.000098 publish_rate:=1000.0'.split()


def _ros_args(node: str, params: list[str]) -> list[str]:
    argv = [sys.executable, '-m', f'maglev_ros.nodes.{node}', '--ros-args']
    for p in params:
        argv += ['-p', p]
    return argv


class _Observer:
    """Arrival time and stamp of every estimate, in a background executor."""

    def __init__(self) -> None:
        import rclpy
        from nav_msgs.msg import Odometry

        from maglev_ros.nodes.qos import SENSOR_QOS
        from maglev_ros.nodes.runtime import Spinner
        from maglev_ros.topics import ESTIMATE_TOPIC

        self.context = rclpy.Context()
        rclpy.init(context=self.context, args=[])
        self.node = rclpy.create_node('estimator_node_observer', context=self.context)
        self.arrivals: list[tuple[float, bytes]] = []
        self.node.create_subscription(
            Odometry,
            ESTIMATE_TOPIC,
            lambda raw: self.arrivals.append((time.monotonic(), raw)),
            SENSOR_QOS,
            raw=True,
        )
        self.spinner = Spinner(self.context, [self.node])

    def close(self) -> None:
        import rclpy

        self.spinner.close()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _stamp_s(raw: bytes) -> float:
    sec, nanosec = (
        int.from_bytes(raw[4:8], 'little', signed=True),
        int.from_bytes(raw[8:12], 'little'),
    )
    return sec + 1e-9 * nanosec


def run_once(stream_thread: bool, seconds: float, warmup: float, env: dict) -> dict:
    """Run simulator and estimator for warmup + seconds; return the figures."""
    observer = _Observer()
    est = [*_EST, f'stream_thread:={"true" if stream_thread else "false"}']
    procs = Processes([_ros_args('simulator', _SIM), _ros_args('estimator', est)], env)
    try:
        deadline = time.monotonic() + 60.0
        while not observer.arrivals and time.monotonic() < deadline and procs.running():
            time.sleep(0.05)
        if not observer.arrivals:
            raise SystemExit(f'no estimate within 60 s; output:\n{procs.tail()}')
        time.sleep(warmup)
        pids = [p.pid for p in procs.procs]
        cpu0 = [cpu_seconds(pid) for pid in pids]
        start, n0 = time.monotonic(), len(observer.arrivals)
        time.sleep(seconds)
        wall = time.monotonic() - start
        cpu = [100.0 * (cpu_seconds(pid) - c) / wall for pid, c in zip(pids, cpu0, strict=True)]
        window = observer.arrivals[n0:]
    finally:
        procs.stop()
        observer.close()
    arrival = np.array([t for t, _ in window])
    stamp = np.array([_stamp_s(raw) for _, raw in window])
    lag = 1e3 * (arrival - stamp)
    lag -= lag.min() if lag.size else 0.0
    span = stamp[-1] - stamp[0] if stamp.size > 1 else 0.0
    return {
        'variant': 'stream thread' if stream_thread else 'executor',
        'cpu_sim': cpu[0],
        'cpu_est': cpu[1],
        'fraction': len(window) / (seconds * 1000.0),
        'span': span / seconds,
        'lag50': float(np.median(lag)) if lag.size else float('nan'),
        'lag99': float(np.percentile(lag, 99)) if lag.size else float('nan'),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=10.0, help='measured window per run, s')
    ap.add_argument('--warmup', type=float, default=3.0, help='s after the first estimate')
    ap.add_argument('--repeats', type=int, default=2, help='runs of each variant')
    args = ap.parse_args()
    env = benchmark_environment(DOMAIN)
    load = os.getloadavg()[0]
    print(f'load average {load:.2f}, {os.cpu_count()} CPUs')
    results = []
    for _ in range(args.repeats):
        for stream_thread in (False, True):
            r = run_once(stream_thread, args.seconds, args.warmup, env)
            results.append(r)
            print(
                f'{r["variant"]:>13}: estimator CPU {r["cpu_est"]:5.1f} %, simulator '
                f'{r["cpu_sim"]:5.1f} %; estimates {r["fraction"]:.3f} of 1000/s, '
                f'stamps {r["span"]:.3f} of real time; lag p50 {r["lag50"]:.1f} ms, '
                f'p99 {r["lag99"]:.1f} ms',
                flush=True,
            )
    med = {}
    for variant in ('executor', 'stream thread'):
        rows = [r for r in results if r['variant'] == variant]
        med[variant] = {
            k: float(np.median([r[k] for r in rows])) for k in rows[0] if k != 'variant'
        }
        m = med[variant]
        print(
            f'median {variant:>13}: estimator CPU {m["cpu_est"]:.1f} %, estimates '
            f'{m["fraction"]:.3f}, lag p50 {m["lag50"]:.1f} ms, p99 {m["lag99"]:.1f} ms'
        )
    ratio = med['executor']['cpu_est'] / med['stream thread']['cpu_est']
    print(f'estimator CPU, executor (baseline) / stream thread: {ratio:.2f}x')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
