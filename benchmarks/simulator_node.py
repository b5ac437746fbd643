"""The real-time simulator node against a baseline checkout's, in the same run.

Starts ``python -m maglev_ros.nodes.simulator`` in real time (5 kHz, magnet
fixed, markers off) from this checkout and from ``--baseline`` (another
checkout, e.g. the main branch), one at a time and alternating, each for
``--seconds`` after a warm-up. This process subscribes every sample topic
(three fields, the true state, the currents, ``/clock``), as a recorder does,
so the node serialises and publishes all of them. Per run it prints the
node's CPU (user + system over the window: % of one core, and per sample
stamped), its real-time factor (simulated time of the currents' stamps over
wall time), the samples this listener received and those it missed (the
listener's own speed: one Python process taking every topic), and the CPU of
the node's threads; then the medians and the ratios of this checkout over the
baseline.

Usage::

    python benchmarks/simulator_node.py --baseline /path/to/other/checkout

Real-time figures on a shared machine are noisy: compare the ratios of one
run, and repeat (``--rounds``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from process_cpu import (  # noqa: E402
    Processes,
    benchmark_environment,
    cpu_seconds,
    thread_cpu_seconds,
)

HERE = Path(__file__).resolve().parent.parent
RATE = 5000.0


def _listener(ctx):
    """Build a node taking every sample topic raw; return it and its count of the currents."""
    import rclpy
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState, MagneticField

    from maglev_ros.cdr.reader import RawFieldReader
    from maglev_ros.nodes.qos import SENSOR_QOS
    from maglev_ros.topics import CLOCK_TOPIC, CURRENTS_TOPIC, TRUE_STATE_TOPIC, field_topic

    node = rclpy.create_node('simulator_benchmark_listener', context=ctx)
    reader = RawFieldReader('sensor_msgs/msg/JointState', ())
    state = {'count': 0, 'last_ns': -1}

    def on_currents(raw):
        state['count'] += 1
        state['last_ns'] = reader.read(raw)[0]

    node.create_subscription(JointState, CURRENTS_TOPIC, on_currents, SENSOR_QOS, raw=True)
    for k in range(3):
        node.create_subscription(MagneticField, field_topic(k), len, SENSOR_QOS, raw=True)
    node.create_subscription(Odometry, TRUE_STATE_TOPIC, len, SENSOR_QOS, raw=True)
    node.create_subscription(Clock, CLOCK_TOPIC, len, SENSOR_QOS, raw=True)
    return node, state


def run_once(checkout: Path, env: dict, ctx, seconds: float, warmup: float) -> dict:
    """Run one simulator node from ``checkout``; return its CPU, RTF and samples."""
    from maglev_ros.nodes.runtime import Spinner

    node, state = _listener(ctx)
    spinner = Spinner(ctx, [node])
    argv = [sys.executable, '-m', 'maglev_ros.nodes.simulator', '--ros-args',
            '-p', 'magnet:=fixed', '-p', 'marker_rate:=0.0']  # fmt: skip
    procs = Processes([argv], env | {'PYTHONPATH': str(checkout)})
    try:
        deadline = time.monotonic() + 60.0
        while state['count'] == 0:
            if time.monotonic() > deadline or not procs.running():
                raise RuntimeError(f'no samples from {checkout}:\n{procs.tail()}')
            time.sleep(0.05)
        time.sleep(warmup)
        pid = procs.procs[0].pid
        c0, t0, n0, s0 = cpu_seconds(pid), time.monotonic(), state['count'], state['last_ns']
        threads0 = thread_cpu_seconds(pid)
        time.sleep(seconds)
        c1, t1, n1, s1 = cpu_seconds(pid), time.monotonic(), state['count'], state['last_ns']
        threads = {k: v - threads0.get(k, 0.0) for k, v in thread_cpu_seconds(pid).items()}
        if not procs.running():
            raise RuntimeError(f'the node from {checkout} stopped:\n{procs.tail()}')
    finally:
        procs.stop()
        spinner.close()
        node.destroy_node()
    wall = t1 - t0
    stamped = round((s1 - s0) * 1e-9 * RATE)
    return {
        'cpu': 100.0 * (c1 - c0) / wall,
        'us_per_sample': 1e6 * (c1 - c0) / max(stamped, 1),
        'rtf': (s1 - s0) * 1e-9 / wall,
        'received': n1 - n0,
        'lost': stamped - (n1 - n0),
        'threads': {k: 100.0 * v / wall for k, v in threads.items() if v > 0.01 * wall},
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--baseline', type=Path, required=True, help='checkout to compare with')
    parser.add_argument('--seconds', type=float, default=10.0, help='measured s per run')
    parser.add_argument('--warmup', type=float, default=3.0, help='s before measuring')
    parser.add_argument('--rounds', type=int, default=2, help='runs of each checkout')
    parser.add_argument('--domain', type=int, default=57, help='ROS_DOMAIN_ID')
    args = parser.parse_args()
    if not (args.baseline / 'maglev_ros' / 'nodes' / 'simulator.py').is_file():
        parser.error(f'--baseline {args.baseline}: no maglev_ros/nodes/simulator.py there')
    env = benchmark_environment(args.domain)
    import rclpy

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    results: dict[str, list[dict]] = {'baseline': [], 'this': []}
    try:
        for _ in range(args.rounds):
            for name, checkout in (('baseline', args.baseline), ('this', HERE)):
                r = run_once(checkout, env, ctx, args.seconds, args.warmup)
                results[name].append(r)
                print(
                    f'{name:8s} CPU {r["cpu"]:5.1f} % ({r["us_per_sample"]:.0f} us/sample)  '
                    f'RTF {r["rtf"]:.3f}  '
                    f'received {r["received"]}  lost {r["lost"]}  threads '
                    + ', '.join(f'{k} {v:.1f} %' for k, v in sorted(r['threads'].items())),
                    flush=True,
                )
    finally:
        rclpy.shutdown(context=ctx)
    cpu = {k: statistics.median(r['cpu'] for r in v) for k, v in results.items()}
    per = {k: statistics.median(r['us_per_sample'] for r in v) for k, v in results.items()}
    rtf = {k: statistics.median(r['rtf'] for r in v) for k, v in results.items()}
    print(f'median CPU: this {cpu["this"]:.1f} %, baseline {cpu["baseline"]:.1f} % '
          f'(ratio {cpu["this"] / cpu["baseline"]:.2f})')  # fmt: skip
    print(f'median CPU per sample: this {per["this"]:.0f} us, baseline {per["baseline"]:.0f} us '
          f'(ratio {per["this"] / per["baseline"]:.2f})')  # fmt: skip
    print(f'median RTF: this {rtf["this"]:.3f}, baseline {rtf["baseline"]:.3f} '
          f'(ratio {rtf["this"] / rtf["baseline"]:.3f})')  # fmt: skip
    print(f'load average: {" ".join(f"{x:.2f}" for x in os.getloadavg())}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
