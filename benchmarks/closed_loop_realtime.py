"""The closed loop in real time at 5 kHz: hold RMS and the CPU of each process.

Issue 9's "Real time" point: the simulator (``mode: realtime``, V2, magnet
free at its equilibrium, coil dynamics, 0.1 mT noise, 0.098 mT steps, one
sample of sensor delay), the estimator (KF) and the controller (LQR) run for
``--seconds`` (default 60) of wall time, in two set-ups:

``composed``
    the three nodes in one process, on one executor (a child process of this
    script, ``--composed-child``), the estimator and the controller with
    ``intra_process: true``: samples, estimates and commands handed over in
    the simulator's thread, one burst of latency;
``launch``
    ``ros2 launch maglev_ros closed_loop.launch.xml``: one process per node.
    Needs ``ros2`` and the package's install tree: ``source install/setup.bash``
    first, or pass ``--install PREFIX`` (a colcon install prefix, e.g.
    ``install/maglev_ros``).

This script observes ``maglev/state/true`` (messages stored raw, decoded at
the end: the observer costs little) and reads each process's CPU time from
``/proc`` over the run. Printed per set-up: samples received against
5000/s x seconds (the real-time factor the observer saw), hold RMS and the
largest excursion of x, y, z - z_eq (from the start, the magnet starts at
rest at the equilibrium), whether it crashed, and the CPU of each process in
% of one core. The baseline of the ratio is the composed set-up, measured in
the same run.

Usage::

    python benchmarks/closed_loop_realtime.py                        # 60 s each
    python benchmarks/closed_loop_realtime.py --seconds 10 --only composed
    python benchmarks/closed_loop_realtime.py --install /path/install/maglev_ros

Run it on a quiet machine: real time at 5 kHz on a loaded 2-core machine
falls behind (the simulator then holds commands and may lose the magnet).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from process_cpu import Processes, benchmark_environment, cpu_seconds

RATE = 5000.0
DOMAIN = 77  # ROS_DOMAIN_ID of the runs (localhost only)
_SIM = [
    ('params', 'maggy_v2'),
    ('magnet', 'free'),
    ('mode', 'realtime'),
    ('coil_dynamics', True),
    ('sensor_delay', 1),
    ('sensor_noise', 1e-4),
    ('sensor_quantization', 0.098e-3),
    ('seed', 0),
    ('wait_for_controller', True),
    ('start_subscribers', 1),
]
_EST = [('params', 'maggy_v2'), ('sensor_noise', 1e-4), ('quantization', 0.098e-3)]
_CTRL = [('params', 'maggy_v2'), ('mode', 'lqr')]


def composed_child(control_rate: float) -> int:
    """Run simulator, estimator and controller in this process until SIGINT.

    Parameters
    ----------
    control_rate : float
        Estimates and commands per second, Hz (the launch file's ``control_rate``).
    """
    from rclpy.parameter import Parameter

    from maglev_ros.nodes.controller import ControllerNode, ControllerParameterError
    from maglev_ros.nodes.estimator import EstimatorNode, EstimatorParameterError
    from maglev_ros.nodes.runtime import run_nodes
    from maglev_ros.nodes.simulator import SimulatorNode, SimulatorParameterError

    def build(cls, values):
        return lambda: cls(parameter_overrides=[Parameter(k, value=v) for k, v in values])

    # composed: samples, estimates and commands handed over in-process (intra_process)
    est = [*_EST, ('publish_rate', control_rate), ('intra_process', True)]
    ctrl = [
        *_CTRL,
        ('sample_rate', control_rate),
        ('trigger', 'estimate'),
        ('input_timeout', 0.02),
        ('intra_process', True),
    ]
    return run_nodes(
        [build(SimulatorNode, _SIM), build(EstimatorNode, est), build(ControllerNode, ctrl)],
        [sys.argv[0]],
        'closed_loop_realtime',
        (SimulatorParameterError, EstimatorParameterError, ControllerParameterError),
    )


class Observer:
    """Stores ``maglev/state/true`` messages raw in a background executor."""

    def __init__(self) -> None:
        import rclpy
        from nav_msgs.msg import Odometry

        from maglev_ros.nodes.qos import SENSOR_QOS
        from maglev_ros.topics import TRUE_STATE_TOPIC

        self.context = rclpy.Context()
        rclpy.init(context=self.context, args=[])
        self.node = rclpy.create_node('closed_loop_realtime_observer', context=self.context)
        self.raw: list[bytes] = []
        # taken in a thread of its own, a burst per wake-up (no executor callback per
        # message): the observer's CPU is taken from the graph it observes
        from maglev_ros.nodes.sample_streams import Stream, open_streams

        self.streams = open_streams(
            self.node,
            [Stream(Odometry, TRUE_STATE_TOPIC, self.raw.append)],
            SENSOR_QOS,
            burst=lambda taken: self.raw.extend(taken[0]),
        )
        from maglev_ros.nodes.runtime import Spinner

        self.spinner = Spinner(self.context, [self.node])

    def positions(self) -> np.ndarray:
        """Return the position of every message received, m, shape (N, 3)."""
        from nav_msgs.msg import Odometry
        from rclpy.serialization import deserialize_message

        out = np.empty((len(self.raw), 3))
        for i, data in enumerate(self.raw):
            p = deserialize_message(data, Odometry).pose.pose.position
            out[i] = p.x, p.y, p.z
        return out

    def close(self) -> None:
        """Stop spinning and shut the observer's context down."""
        import rclpy

        self.spinner.close()
        if self.streams is not None:
            self.streams.close()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def run_setup(label: str, argv: list[str], env: dict, seconds: float, z_eq: float) -> dict:
    """Start ``argv`` (own process group), observe for ``seconds``, Ctrl-C it; print figures."""
    observer = Observer()
    procs = Processes([argv], env)
    try:
        deadline = time.monotonic() + 180.0  # the first start compiles numba kernels
        while not observer.raw and time.monotonic() < deadline and procs.running():
            time.sleep(0.1)
        if not observer.raw:
            raise SystemExit(f'{label}: no maglev/state/true; output:\n' + procs.tail())
        time.sleep(1.0)  # all processes up and steady
        pids = procs.names()
        cpu0 = {pid: cpu_seconds(pid) for pid in pids}
        n0, t0 = len(observer.raw), time.monotonic()
        print(f'{label}: running {seconds:g} s ...', flush=True)
        time.sleep(seconds)
        wall = time.monotonic() - t0
        cpu = {pid: cpu_seconds(pid) - cpu0[pid] for pid in pids}
        n1 = len(observer.raw)
    finally:
        procs.stop()
        observer.close()
    pos = observer.positions()[n0:n1]
    if not len(pos):
        print(f'{label}: no sample in the {seconds:g} s window; output:\n' + procs.tail())
        nan = np.full(3, np.nan)
        return {'rms': nan, 'worst': nan, 'crashed': True, 'cpu': 0.0}
    err = pos - np.array([0.0, 0.0, z_eq])
    crashed = any('magnet crashed' in line for line in procs.lines)
    rms = np.sqrt(np.mean(err**2, axis=0))
    worst = np.max(np.abs(err), axis=0)
    print(
        f'{label}: {n1 - n0} samples in {wall:.1f} s = {(n1 - n0) / (RATE * wall):.3f} of real '
        f'time; hold RMS x y z {" ".join(f"{1e6 * v:.1f}" for v in rms)} um, largest '
        f'{" ".join(f"{1e6 * v:.1f}" for v in worst)} um; crashed {crashed}'
    )
    for pid, name in pids.items():
        if cpu[pid] > 0.005 * wall:
            print(f'    {name:<40} pid {pid:>7}: CPU {100 * cpu[pid] / wall:5.1f} % of a core')
    total = sum(cpu.values())
    print(f'    total CPU {100 * total / wall:.1f} % of a core', flush=True)
    return {'rms': rms, 'worst': worst, 'crashed': crashed, 'cpu': total / wall}


def main() -> int:
    """Run the set-ups and print their figures."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=60.0, help='s of wall time per set-up')
    ap.add_argument('--only', choices=('composed', 'launch'), help='one set-up only')
    ap.add_argument('--install', type=Path, help='colcon install prefix of maglev_ros')
    ap.add_argument(
        '--control-rate',
        type=float,
        default=1000.0,
        help='estimates and commands per second, Hz (default 1000: one per 1 ms burst)',
    )
    ap.add_argument('--composed-child', action='store_true', help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.composed_child:
        return composed_child(args.control_rate)
    if not args.seconds > 0:
        print(f'closed_loop_realtime: error: --seconds must be > 0, got {args.seconds}')
        return 2
    from maglev_ros.physics import make_model
    from maglev_ros.physics.equilibria import find_equilibria

    z_eq = find_equilibria(make_model('maggy_v2'))[0].z
    env = benchmark_environment(DOMAIN)
    results = {}
    print(f'load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs', flush=True)
    if args.only in (None, 'composed'):
        argv = [
            sys.executable,
            __file__,
            '--composed-child',
            '--control-rate',
            str(args.control_rate),
        ]
        results['composed'] = run_setup('composed', argv, env, args.seconds, z_eq)
    if args.only in (None, 'launch'):
        launch_env = dict(env)
        if args.install is not None:
            prefix = args.install.resolve()
            site = next(prefix.glob('lib/python3*/site-packages'), None)
            if site is None:
                print(f'closed_loop_realtime: error: --install {prefix}: no site-packages')
                return 2
            venv = Path(sys.executable).parent.parent
            launch_env['AMENT_PREFIX_PATH'] = os.pathsep.join(
                filter(None, [str(prefix), str(venv), env.get('AMENT_PREFIX_PATH')])
            )
            launch_env['PYTHONPATH'] = os.pathsep.join(
                filter(None, [str(site), env.get('PYTHONPATH')])
            )
            launch_env['PATH'] = os.pathsep.join([str(Path(sys.executable).parent), env['PATH']])
        argv = ['ros2', 'launch', 'maglev_ros', 'closed_loop.launch.xml']
        argv.append(f'control_rate:={args.control_rate}')
        results['launch'] = run_setup('launch', argv, launch_env, args.seconds, z_eq)
    if len(results) == 2 and results['composed']['cpu'] > 0 and results['launch']['cpu'] > 0:
        c, s = results['composed'], results['launch']
        print(
            f'CPU of separate processes over composed (baseline, same run): '
            f'{s["cpu"] / c["cpu"]:.2f}x'
        )
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
