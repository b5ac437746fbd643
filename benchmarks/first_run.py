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

Usage::

    python benchmarks/first_run.py [--skip-lab]

Wall times on a shared machine: run it when the load is low, and read the
load printed at the start and end.
"""

from __future__ import annotations

import argparse
import os
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


def _node_ready(cache: str) -> float:
    """Return the s until the simulator node's first field message arrives."""
    code = (
        'import sys, time, rclpy\n'
        'from rclpy.node import Node\n'
        'from rclpy.qos import qos_profile_sensor_data\n'
        'from sensor_msgs.msg import MagneticField\n'
        'rclpy.init(); node = Node("first_run_probe"); got = []\n'
        'node.create_subscription(MagneticField, "/maglev/sensor_0/field",'
        ' lambda m: got.append(1), qos_profile_sensor_data)\n'
        'print("ready", flush=True)\n'
        'while not got: rclpy.spin_once(node, timeout_sec=0.1)\n'
        'print("got", flush=True)\n'
    )
    env = _env(cache)
    probe = subprocess.Popen(
        [sys.executable, '-c', code], env=env, stdout=subprocess.PIPE, text=True
    )
    probe.stdout.readline()
    start = time.monotonic()
    node = subprocess.Popen(
        [sys.executable, '-m', 'maglev_ros.nodes.simulator'],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        probe.stdout.readline()
        return time.monotonic() - start
    finally:
        node.send_signal(signal.SIGINT)
        node.wait(timeout=30)
        probe.kill()
        probe.wait()


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
    parser.add_argument('--skip-lab', action='store_true', help='only the node')
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
    print(f'load average at the end: {os.getloadavg()[0]:.1f}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
