"""Benchmark the first run after an install against a warm run: the main job and a node.

The first run compiles the numba kernels a command uses (a cache miss), later
runs load them from numba's cache. Each case runs as its own process on a
fresh private cache (``NUMBA_CACHE_DIR`` in a temporary directory), so the
checkout's own ``__pycache__`` plays no part:

* **main job**: ``maglev-lab --out DIR`` (README command 1), first then warm;
  the figure is the wall time of each and the difference (the bar: at most
  60 s slower).
* **node**: ``maglev_simulator`` started, time until a subscriber receives
  its first field message, first then warm (the bar: 30 s), and how long it
  takes to end after SIGINT 2 s into its compile (the bar: 2 s).
* **after colcon build** (``--after-build``): a copy of the package built with
  ``colcon build`` (whose last step compiles the kernels), then ``ros2 launch
  maglev_ros closed_loop.launch.xml``: time until its first estimate, right
  after the build and warm (the bar: 30 s).

Usage::

    python benchmarks/first_run.py [--skip-lab] [--after-build]

Wall times on a shared machine: run it when the load is low, and read the
load printed at the start and end.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRESS = 'compiling kernels, first run only'


def _env(cache: str) -> dict[str, str]:
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get('PYTHONPATH', '')) if p)
    return dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=path, ROS_DOMAIN_ID='91')


def _lab(cache: str, out: str) -> float:
    start = time.monotonic()
    subprocess.run(
        [sys.executable, '-m', 'maglev_ros.cli.lab', '--out', out, '--quiet'],
        env=_env(cache),
        check=True,
        capture_output=True,
    )
    return time.monotonic() - start


def _first_message(cmd: list[str], env: dict, topic: str, msg: str) -> float:
    """Start ``cmd``; return the s until a probe receives its first ``msg`` on ``topic``."""
    module, name = msg.rsplit('.', 1)
    code = (
        'import rclpy\n'
        'from rclpy.node import Node\n'
        'from rclpy.qos import qos_profile_sensor_data\n'
        f'from {module} import {name}\n'
        'rclpy.init(); node = Node("first_run_probe"); got = []\n'
        f'node.create_subscription({name}, "{topic}",'
        ' lambda m: got.append(1), qos_profile_sensor_data)\n'
        'print("ready", flush=True)\n'
        'while not got: rclpy.spin_once(node, timeout_sec=0.1)\n'
        'print("got", flush=True)\n'
    )
    probe = subprocess.Popen(
        [sys.executable, '-c', code], env=env, stdout=subprocess.PIPE, text=True
    )
    probe.stdout.readline()
    start = time.monotonic()
    node = subprocess.Popen(
        cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    try:
        probe.stdout.readline()
        return time.monotonic() - start
    finally:
        os.killpg(node.pid, signal.SIGINT)
        node.wait(timeout=30)
        probe.kill()
        probe.wait()


def _node_ready(cache: str) -> float:
    """Return the s until the simulator node's first field message arrives."""
    cmd = [sys.executable, '-m', 'maglev_ros.nodes.simulator']
    return _first_message(
        cmd, _env(cache), '/maglev/sensor_0/field', 'sensor_msgs.msg.MagneticField'
    )


def _after_colcon_build(tmp: Path) -> tuple[float, float, float]:
    """Build a copy of the package with colcon; return its s and the launch's first estimate, s.

    The source copy has no ``__pycache__``, so the build compiles every
    kernel; then ``ros2 launch maglev_ros closed_loop.launch.xml`` (the loop
    node) twice: right after the build, and again (warm).
    """
    bin_dir = Path(sys.executable).parent
    src = tmp / 'ws' / 'src' / 'maglev_ros'
    for name in (
        'setup.py',
        'setup.cfg',
        'package.xml',
        'resource',
        'config',
        'launch',
        'maglev_ros',
    ):
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns('__pycache__'))
        else:
            src.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    env = {k: v for k, v in os.environ.items() if k not in ('NUMBA_CACHE_DIR', 'PYTHONPATH')}
    env['PATH'] = os.pathsep.join([str(bin_dir), env.get('PATH', '')])
    start = time.monotonic()
    subprocess.run(
        [str(bin_dir / 'colcon'), 'build', '--packages-select', 'maglev_ros'],
        cwd=tmp / 'ws',
        env=env,
        check=True,
        capture_output=True,
    )
    build = time.monotonic() - start
    prefix = tmp / 'ws' / 'install' / 'maglev_ros'
    site = next(prefix.glob('lib/python3*/site-packages'))
    env.update(
        AMENT_PREFIX_PATH=os.pathsep.join([str(prefix), sys.prefix]),
        PYTHONPATH=str(site),
        ROS_DOMAIN_ID='92',
        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
    )
    cmd = [str(bin_dir / 'ros2'), 'launch', 'maglev_ros', 'closed_loop.launch.xml']
    topic, msg = '/maglev/state/estimate', 'nav_msgs.msg.Odometry'
    return build, _first_message(cmd, env, topic, msg), _first_message(cmd, env, topic, msg)


def _node_stop_during_compile(cache: str) -> float:
    node = subprocess.Popen(
        [sys.executable, '-m', 'maglev_ros.nodes.simulator'],
        env=_env(cache),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    for line in node.stderr:
        if PROGRESS in line:
            break
    time.sleep(2.0)  # well inside the compile
    start = time.monotonic()
    node.send_signal(signal.SIGINT)
    node.wait(timeout=60)
    return time.monotonic() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--skip-lab', action='store_true', help='only the nodes')
    parser.add_argument(
        '--after-build', action='store_true', help='also colcon build and ros2 launch the loop'
    )
    args = parser.parse_args()
    print(f'load average at the start: {os.getloadavg()[0]:.1f}')
    with tempfile.TemporaryDirectory() as tmp:
        if not args.skip_lab:
            cache = str(Path(tmp) / 'lab_cache')
            first = _lab(cache, str(Path(tmp) / 'lab1'))
            warm = _lab(cache, str(Path(tmp) / 'lab2'))
            print(
                f'maglev-lab: first run {first:.0f} s, warm {warm:.0f} s, first - warm '
                f'{first - warm:.0f} s (bar 60 s), ratio {first / warm:.2f}'
            )
        cache = str(Path(tmp) / 'node_cache')
        first = _node_ready(cache)
        warm = _node_ready(cache)
        print(
            f'simulator node, first sample published: first run {first:.1f} s, '
            f'warm {warm:.1f} s (bar 30 s), ratio {first / warm:.2f}'
        )
        stop = _node_stop_during_compile(str(Path(tmp) / 'stop_cache'))
        print(f'simulator node, SIGINT 2 s into its compile: ended after {stop:.2f} s (bar 2 s)')
        if args.after_build:
            build, first, warm = _after_colcon_build(Path(tmp))
            print(
                f'colcon build (kernels compiled by it) {build:.0f} s; ros2 launch '
                f'closed_loop.launch.xml, first estimate: right after the build {first:.1f} s, '
                f'warm {warm:.1f} s (bar 30 s), ratio {first / warm:.2f}'
            )
    print(f'load average at the end: {os.getloadavg()[0]:.1f}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
