"""Benchmarks of the lab pipeline: bag -> data set throughput (``maglev-bag2data``), bag writer.

bag2data: a bag of 5 kHz lockstep data (one sensor ``MagneticField``, the coil
currents ``JointState`` and the commands ``Float64MultiArray``; 10 s, 150 000
messages, MCAP and sqlite3) is read in the same run by

* **bare**: a plain rosbags loop, ``Reader.messages`` over the three topics and
  ``Typestore.deserialize_cdr`` of every message, nothing kept;
* **bag2data**: :func:`maglev_ros.bags.read_bag` with 3 outputs (field x, y, z)
  and 8 inputs (4 currents, 4 commands): read, decode, align and build the
  ``IdData`` (equal-layout messages decoded by strided numpy reads);
* **bag2data deserialising**: the same with ``fast=False``, the general path
  that deserialises every message (used when a topic's layout varies).

Throughput is messages per CPU second of this process (best of ``--repeat``,
the two interleaved; CPU time because the machine is shared and wall time
swings with the other jobs), and the ratio bag2data / bare against the
target 0.8; the wall-time ratio is printed too.  The bag is built with rosbags' own
serialiser (rclpy is not needed).

writer: :class:`maglev_ros.bags.BagWriter` throughput with pre-serialised
messages, what the recorder node does per received message, and the time
``close()`` takes to finalise the bag.

Run: ``/tmp/venv/bin/python benchmarks/lab.py [--quick] [--part bag2data|writer]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Reader

from maglev_ros.bags import BagWriter, read_bag
from maglev_ros.bags.typestore import jazzy_typestore

RATE_HZ = 5000.0
TARGET_RATIO = 0.8
TOPICS = ('/maglev/sensor_0/field', '/maglev/currents', '/maglev/currents/command')
OUTPUTS = [f'maglev/sensor_0/field:magnetic_field.{a}' for a in 'xyz']
INPUTS = [f'maglev/currents:effort[{i}]' for i in range(4)] + [
    f'maglev/currents/command:data[{i}]' for i in range(4)
]


def build_bag(path: Path, seconds: float, storage: str) -> int:
    """Write a lockstep bag of ``seconds`` at 5 kHz; return the message count."""
    store = jazzy_typestore()
    types = store.types
    Time, Header = types['builtin_interfaces/msg/Time'], types['std_msgs/msg/Header']
    Vector3 = types['geometry_msgs/msg/Vector3']
    Field, Joints = types['sensor_msgs/msg/MagneticField'], types['sensor_msgs/msg/JointState']
    Array = types['std_msgs/msg/Float64MultiArray']
    Layout = types['std_msgs/msg/MultiArrayLayout']
    n = int(round(seconds * RATE_HZ))
    rng = np.random.default_rng(0)
    field, current = rng.normal(0.0, 1e-3, (n, 3)), rng.uniform(-1.0, 1.0, (n, 4))
    t0, step = 1_700_000_000_000_000_000, int(round(1e9 / RATE_HZ))
    cov, names = np.zeros(9), ['x+', 'x-', 'y+', 'y-']
    with BagWriter(path, storage=storage, metadata={'benchmark': 'lab.py'}) as bag:
        handles = [
            bag.add_topic(TOPICS[0], 'sensor_msgs/msg/MagneticField'),
            bag.add_topic(TOPICS[1], 'sensor_msgs/msg/JointState'),
            bag.add_topic(TOPICS[2], 'std_msgs/msg/Float64MultiArray'),
        ]
        for k in range(n):
            stamp = t0 + k * step
            header = Header(
                stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id='maglev_sensor_0'
            )
            msgs = (
                Field(
                    header=header, magnetic_field=Vector3(*field[k]), magnetic_field_covariance=cov
                ),
                Joints(
                    header=header,
                    name=names,
                    position=np.zeros(0),
                    velocity=np.zeros(0),
                    effort=current[k],
                ),
                Array(layout=Layout(dim=[], data_offset=0), data=current[k]),
            )
            for handle, msg in zip(handles, msgs, strict=True):
                bag.write(handle, stamp + 1000, bytes(store.serialize_cdr(msg, handle.msgtype)))
    return 3 * n


def bare_loop(path: Path) -> int:
    """Read and deserialise every message of the three topics with plain rosbags."""
    store = jazzy_typestore()
    count = 0
    with Reader(path) as reader:
        connections = [c for c in reader.connections if c.topic in TOPICS]
        for connection, _, raw in reader.messages(connections=connections):
            store.deserialize_cdr(raw, connection.msgtype)
            count += 1
    return count


def bag2data(path: Path) -> int:
    """Convert the bag with read_bag; return the samples."""
    return read_bag(path, OUTPUTS, INPUTS).data.N


def bag2data_deserializing(path: Path) -> int:
    """Convert the bag with read_bag's general path (deserialise every message)."""
    return read_bag(path, OUTPUTS, INPUTS, fast=False).data.N


def timed(func, path: Path) -> tuple[float, float, int]:
    """CPU time and wall time of one call, s, and the call's result."""
    cpu, wall = time.process_time(), time.perf_counter()
    result = func(path)
    return time.process_time() - cpu, time.perf_counter() - wall, result


def measure_bag2data(seconds: float, repeat: int) -> list[dict]:
    """bag2data vs the bare rosbags loop on the same bags (MCAP and sqlite3)."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for storage in ('mcap', 'sqlite3'):
            path = Path(tmp) / storage
            messages = build_bag(path, seconds, storage)
            # interleaved, so that load changes by other jobs hit both alike
            funcs = (bare_loop, bag2data, bag2data_deserializing)
            times = np.full((len(funcs), repeat, 2), np.inf)  # CPU, wall
            for k in range(repeat):
                for f, func in enumerate(funcs):
                    *times[f, k], result = timed(func, path)
                    assert func is bare_loop or result == messages // 3, (result, messages)
            (cpu_bare, wall_bare), (cpu_ours, wall_ours), (cpu_slow, _) = times.min(axis=1)
            rows.append(
                {
                    'storage': storage,
                    'messages': messages,
                    'bare_msgs_per_s': messages / cpu_bare,
                    'bag2data_msgs_per_s': messages / cpu_ours,
                    'ratio': cpu_bare / cpu_ours,
                    'wall_ratio': wall_bare / wall_ours,
                    'deserializing_msgs_per_s': messages / cpu_slow,
                    'deserializing_ratio': cpu_bare / cpu_slow,
                }
            )
    return rows


def report_bag2data(rows: list[dict], seconds: float) -> None:
    """Print the bag2data table."""
    print(f'bag2data: {seconds:g} s of 5 kHz lockstep data (sensor + currents + commands)')
    print(
        'throughput in messages per CPU second (best of the repeats); ratio = bag2data '
        f'/ bare, target >= {TARGET_RATIO}'
    )
    print(
        '| storage | messages | bare rosbags loop (msg/s) | bag2data (msg/s) | ratio (CPU) '
        '| ratio (wall) | bag2data deserialising (msg/s) | its ratio (CPU) |'
    )
    print('|---|---|---|---|---|---|---|---|')
    for r in rows:
        verdict = 'met' if r['ratio'] >= TARGET_RATIO else 'MISSED'
        print(
            f'| {r["storage"]} | {r["messages"]:,} | {r["bare_msgs_per_s"]:,.0f} | '
            f'{r["bag2data_msgs_per_s"]:,.0f} | {r["ratio"]:.2f} ({verdict}) | '
            f'{r["wall_ratio"]:.2f} | {r["deserializing_msgs_per_s"]:,.0f} | '
            f'{r["deserializing_ratio"]:.2f} |'
        )


def measure_writer(messages: int) -> list[dict]:
    """BagWriter.write throughput with pre-serialised messages (what a recorder does)."""
    store = jazzy_typestore()
    field = store.types['sensor_msgs/msg/MagneticField']
    header = store.types['std_msgs/msg/Header'](
        stamp=store.types['builtin_interfaces/msg/Time'](sec=0, nanosec=0),
        frame_id='maglev_sensor_0',
    )
    raw = bytes(
        store.serialize_cdr(
            field(
                header=header,
                magnetic_field=store.types['geometry_msgs/msg/Vector3'](0.0, 0.0, 0.05),
                magnetic_field_covariance=np.zeros(9),
            ),
            'sensor_msgs/msg/MagneticField',
        )
    )
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for storage in ('mcap', 'sqlite3'):
            with BagWriter(Path(tmp) / storage, storage=storage) as bag:
                topic = bag.add_topic(TOPICS[0], 'sensor_msgs/msg/MagneticField')
                cpu = time.process_time()
                for k in range(messages):
                    bag.write(topic, k, raw)
                cpu = time.process_time() - cpu
                close = time.process_time()
            close = time.process_time() - close
            rows.append(
                {
                    'storage': storage,
                    'messages': messages,
                    'msgs_per_s': messages / cpu,
                    'close_s': close,
                }
            )
    return rows


def report_writer(rows: list[dict]) -> None:
    """Print the writer table."""
    print('writer: BagWriter.write of pre-serialised MagneticField messages (CPU time)')
    print('| storage | messages | write (msg/s) | close (CPU s) |')
    print('|---|---|---|---|')
    for r in rows:
        print(
            f'| {r["storage"]} | {r["messages"]:,} | {r["msgs_per_s"]:,.0f} | {r["close_s"]:.3f} |'
        )


# --------------------------------------------------------------------------- simulator node
def measure_simulator_rtf(seconds: float, topics: str) -> dict:
    """Real-time factor of the simulator node at 5 kHz, recorder in a second process.

    The simulator (real-time mode, one sensor, magnet fixed, coil dynamics and
    the one-sample sensor delay on) runs in this process on the package's
    executor; ``maglev_ros.nodes.recorder`` runs as its own process recording
    ``topics`` (a ROS list literal), as on a lab PC. The
    real-time factor is simulated time / wall time over ``seconds`` of steady
    running (target >= 1.0: the node keeps up with the board's rate; paced to
    the wall clock, it cannot exceed 1.0, so the headroom, the 200 us sample
    period over the simulator process's CPU time per sample, is printed too), with
    Fast DDS publishing asynchronously as the ``simulator`` executable sets it; the
    recorder's message count against the published samples is reported too.
    """
    import os
    import subprocess
    import sys

    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from maglev_ros.bags import BagReader
    from maglev_ros.nodes import contract
    from maglev_ros.nodes.simulator import SimulatorNode

    domain = 150 + os.getpid() % 50
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    # as the simulator executable's main() does (asynchronous Fast DDS publishing)
    os.environ.setdefault('RMW_FASTRTPS_PUBLICATION_MODE', 'ASYNCHRONOUS')
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / 'rtf'
        recorder = subprocess.Popen(
            [
                sys.executable,
                '-m',
                'maglev_ros.nodes.recorder',
                '--ros-args',
                '-p',
                f'path:={bag}',
                '-p',
                f'topics:={topics}',
                '-p',
                'metadata_node:=""',
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        ctx = Context()
        rclpy.init(context=ctx, domain_id=domain)
        sim = SimulatorNode(
            context=ctx,
            parameter_overrides=[
                Parameter('mode', value='realtime'),
                Parameter('sensors', value=[0]),
                Parameter('magnet', value='fixed'),
                Parameter('start_paused', value=True),
                Parameter('marker_rate', value=0.0),
            ],
        )
        spinner = contract.Spinner(ctx, [sim])
        try:
            deadline = time.monotonic() + 60.0
            while sim.currents_subscribers == 0:
                if time.monotonic() > deadline:
                    raise RuntimeError('the recorder process never subscribed')
                time.sleep(0.05)
            time.sleep(2.0)  # the recorder subscribes topic by topic
            sim.set_paused(False)
            time.sleep(1.0)  # warm-up
            t0, s0, c0 = time.monotonic(), sim.sim.time, time.process_time()
            samples0 = sim.counters['samples']
            time.sleep(seconds)
            t1, s1, c1 = time.monotonic(), sim.sim.time, time.process_time()
            samples = sim.counters['samples'] - samples0
            sim.set_paused(True)
            published = sim.counters['samples']
            overruns = sim.counters['overruns']
            time.sleep(1.0)
        finally:
            spinner.close()
            sim.destroy_node()
            rclpy.try_shutdown(context=ctx)
            recorder.send_signal(2)  # SIGINT: the recorder finalises its bag
            try:
                recorder.wait(timeout=30)
            except subprocess.TimeoutExpired:
                recorder.kill()
                recorder.wait()
        with BagReader(bag) as reader:
            recorded = sum(1 for _ in reader.messages(['/maglev/currents']))
    return {
        'topics': topics,
        'rtf': (s1 - s0) / (t1 - t0),
        'samples': samples,
        'wall_s': t1 - t0,
        'cpu_per_sample_us': (c1 - c0) / max(samples, 1) * 1e6,
        'overruns': overruns,
        'published': published,
        'recorded': recorded,
    }


SIMULATOR_RECORDINGS = (
    '[maglev/sensor_0/field, maglev/currents]',
    '[maglev/sensor_0/field, maglev/currents, maglev/state/true, /clock]',
)


def report_simulator(rows: list[dict]) -> None:
    print('\n## Simulator node real-time factor (5 kHz, 1 sensor, recorder in a 2nd process)\n')
    print(
        '| recorded topics | real-time factor (target >= 1.0) | samples | wall (s) | '
        'simulator-process CPU / sample (us) | headroom (200 us / CPU per sample) | '
        'overruns | recorded / published currents |'
    )
    print('|---|---|---|---|---|---|---|---|')
    for row in rows:
        print(
            f'| {row["topics"]} | {row["rtf"]:.3f} | {row["samples"]:,} | '
            f'{row["wall_s"]:.1f} | {row["cpu_per_sample_us"]:.0f} | '
            f'{200.0 / row["cpu_per_sample_us"]:.2f}x | {row["overruns"]} | '
            f'{row["recorded"]:,} / {row["published"]:,} = '
            f'{row["recorded"] / max(row["published"], 1):.3f} |'
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='2 s of data, 2 repeats')
    parser.add_argument(
        '--part', choices=('bag2data', 'writer', 'simulator'), help='run one measurement only'
    )
    parser.add_argument('--seconds', type=float, default=10.0, help='bag length (s)')
    parser.add_argument('--repeat', type=int, default=3, help='repeats (best is kept)')
    args = parser.parse_args()
    seconds, repeat = (2.0, 2) if args.quick else (args.seconds, args.repeat)
    if args.part in (None, 'bag2data'):
        report_bag2data(measure_bag2data(seconds, repeat), seconds)
    if args.part in (None, 'writer'):
        report_writer(measure_writer(int(seconds * RATE_HZ) * 3))
    if args.part in (None, 'simulator'):
        report_simulator([measure_simulator_rtf(seconds, t) for t in SIMULATOR_RECORDINGS])


if __name__ == '__main__':
    main()
