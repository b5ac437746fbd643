"""The closed loop as separate processes under ``ros2 launch``: hold, latency and CPU per process.

Runs ``ros2 launch maglev_ros closed_loop.launch.xml separate:=true record:=true``
(simulator sensing at ``sample_rate``, publishing the means at ``control_rate``;
estimator, controller and recorder each in its own process) from a colcon install
of the package for ``--seconds`` once the simulator steps, then stops it as a
terminal's Ctrl-C does. Printed:

- the CPU of each process from the simulator's start (user + system, % of one
  core over the time it stepped: the run, or until the magnet was lost), from
  ``/proc`` (:mod:`process_cpu`);
- the command latency the simulator saw: its ``command lag (samples)``
  diagnostic (readings between the newest sample stepped and the sample a
  command answers, sampled once a second), in ms;
- the hold from the bag's true state after 1 s: RMS and largest |x|, |y|.

    colcon build --packages-select maglev_ros      # in a workspace with this package
    python benchmarks/separate_closed_loop.py --install install/maglev_ros --seconds 60

The baseline of the latency is the LQR's design (``command_delay`` control periods);
the CPU shares are of one run, on whatever else the machine runs: say its load.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from process_cpu import Processes, benchmark_environment, cpu_seconds

ROLES = ('maglev_simulator', 'maglev_estimator', 'maglev_controller', 'maglev_recorder')


def _environment(install: Path, domain: int) -> dict[str, str]:
    """Return the environment ``source install/setup.bash`` leaves, in domain ``domain``."""
    env = benchmark_environment(domain)
    site = sorted(install.glob('lib/python3*/site-packages'))
    if not site:
        raise SystemExit(f'{install}: no lib/python3*/site-packages: give a colcon install prefix')
    join = os.pathsep.join
    env['AMENT_PREFIX_PATH'] = join([str(install), sys.prefix])
    env['PYTHONPATH'] = join([str(site[0]), env.get('PYTHONPATH', '')])
    env['PATH'] = join([str(Path(sys.executable).parent), env.get('PATH', '')])
    return env


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


class _CommandLag:
    """The simulator's ``command lag (samples)`` diagnostic, heard once a second."""

    def __init__(self) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState

        from maglev_ros.nodes.qos import SENSOR_QOS

        self.values: list[int] = []
        self.last: dict[str, str] = {}  # the simulator's last diagnostics
        self.recording = False
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('separate_closed_loop_benchmark', context=self.context)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on, 10)
        # arrival (wall clock) of each sample and of the command answering it, by stamp
        self.samples: dict[int, float] = {}
        self.commands: dict[int, float] = {}
        for topic, book in (('/maglev/currents', self.samples),
                            ('/maglev/currents/command', self.commands)):  # fmt: skip
            self.node.create_subscription(
                JointState, topic, lambda m, b=book: b.setdefault(_stamp(m), time.monotonic()),
                SENSOR_QOS,
            )  # fmt: skip
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        try:
            while self.context.ok():
                self.executor.spin_once(timeout_sec=0.2)
        except ExternalShutdownException:
            pass

    def _on(self, msg) -> None:
        for status in msg.status:
            if not status.name.startswith('maglev_simulator') or not self.recording:
                continue
            self.last = {kv.key: kv.value for kv in status.values}
            for kv in status.values:
                if kv.key == 'command lag (samples)' and kv.value.lstrip('-').isdigit():
                    self.values.append(int(kv.value))

    def close(self) -> None:
        import rclpy

        rclpy.shutdown(context=self.context)
        self.thread.join(timeout=2.0)


def _hold(bag: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """RMS and largest |x|, |y| after 1 s (m), and the seconds of state recorded."""
    from maglev_ros.bags import read_bag

    position = [f'maglev/state/true:pose.pose.position.{a}' for a in 'xy']
    data = read_bag(bag, position, allow_gaps=True).data
    y = np.asarray(data.y)[int(round(1.0 / data.Ts)) :]
    if not len(y):
        return np.full(2, np.nan), np.full(2, np.nan), len(data.y) * data.Ts
    return np.sqrt(np.mean(y**2, axis=0)), np.abs(y).max(axis=0), len(data.y) * data.Ts


def main() -> None:
    """Run the launch and print its figures (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--install', type=Path, required=True, help='colcon install prefix')
    p.add_argument('--seconds', type=float, default=60.0, help='s of hold measured')
    p.add_argument('--domain', type=int, default=77)
    p.add_argument('args', nargs='*', help='more launch arguments (name:=value)')
    a = p.parse_args()
    env = _environment(a.install.resolve(), a.domain)
    bag = Path(tempfile.mkdtemp(prefix='separate_')) / 'bag'
    lag = _CommandLag()
    launch = Processes([[
        'ros2', 'launch', 'maglev_ros', 'closed_loop.launch.xml', 'separate:=true',
        'record:=true', f'bag:={bag}', *a.args,
    ]], env)  # fmt: skip
    try:
        while not any('started: stepping' in line for line in launch.lines):
            if not launch.running():
                raise SystemExit(f'the launch ended:\n{launch.tail()}')
            time.sleep(0.5)
        pids = {name: pid for pid, name in launch.names().items() if name in ROLES}
        before = {name: cpu_seconds(pid) for name, pid in pids.items()}
        lag.recording = True
        start = time.monotonic()
        time.sleep(a.seconds)
        used = {name: cpu_seconds(pid) - before[name] for name, pid in pids.items()}
        wall = time.monotonic() - start
        lag.recording = False
    finally:
        launch.stop()
        lag.close()
    both = sorted(set(lag.samples) & set(lag.commands))
    if both:
        rtt = np.array([lag.commands[k] - lag.samples[k] for k in both]) * 1e3
        print(f'sample -> command (arrivals here, {len(rtt)} pairs): median {np.median(rtt):.2f} '
              f'ms, p99 {np.percentile(rtt, 99):.2f} ms, largest {rtt.max():.2f} ms; first 0.5 s '
              f'median {np.median(rtt[:500]):.2f} ms')  # fmt: skip
    print('simulator:', ', '.join(f'{k} {v}' for k, v in lag.last.items()))
    if both and os.environ.get('SHOW_RTT'):
        print(np.round(rtt[:80], 1).tolist())
    rms, largest, recorded = _hold(bag)
    simulated = float(lag.last.get('simulated time (s)', 'nan'))
    if simulated < wall:  # the magnet was lost: the shares of the time it was stepped
        wall = simulated
    print(f'load average {os.getloadavg()[0]:.1f}; {recorded:.1f} s of state recorded; CPU '
          f'over {wall:.1f} s of stepping')  # fmt: skip
    for name in ROLES:
        if name in used:
            print(f'  {name:<18} {100 * used[name] / wall:5.1f} % of a core')
    print(f'  all four           {100 * sum(used.values()) / wall:5.1f} %')
    if lag.values:
        rate = next((float(x.split(':=')[1]) for x in a.args if x.startswith('sample_rate:=')),
                    5000.0)  # fmt: skip
        ms = np.array(lag.values) * 1e3 / rate  # readings
        print(f'command lag (simulator, {len(ms)} snapshots): median {np.median(ms):.1f} ms, '
              f'largest {ms.max():.1f} ms')  # fmt: skip
    print(
        f'hold after 1 s: RMS x, y {rms[0] * 1e6:.0f}, {rms[1] * 1e6:.0f} um; '
        f'largest {largest[0] * 1e6:.0f}, {largest[1] * 1e6:.0f} um'
    )
    lost = any('magnet crashed' in line for line in launch.lines)
    print('magnet LOST' if lost else 'magnet held')


if __name__ == '__main__':
    main()
