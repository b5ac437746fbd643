"""Benchmark: the driver's V4x PC-control loop: steps per second and command latency.

The board is the virtual V4x PC-control board (``maglev-virtual-board --firmware
v4x_pc``, physics plant, magnet fixed) in its own process on a pty: host and
emulator share this machine's cores, as a host and a real board would not.

A step reads the field and commands the coils. The latency is the time from the
host stamp of a sample (its sensor reply arrived) to the write of the command
computed from it. Measured in the same run, alternating, on the same board:

* **baseline**, the lab host's pattern: pyserial per request (``reset_input_buffer``,
  ``write``, ``flush``, ``read_until`` 0x00) with the ``cobs`` package: ``01``, then
  the command from its reply as ``03`` (two round trips; the command goes out at once);
* **cycle loop**: ``V4xPcLink.cycle`` back to back, no callback: what the link
  alone reaches (``01 02 03`` in one round trip);
* **poller 1000 Hz / free**: ``hardware.v4x_pc_poller`` (what the driver node runs),
  with a controller answering each sample in the I/O thread (as a composed loop
  does): the command goes out with the next step's ``01 02 03`` (one round trip);
* **driver node**: ``DriverNode(firmware v4x_pc)`` at 1000 Hz with a controller node in
  the same process answering each ``maglev/currents`` message on
  ``maglev/currents/command`` over DDS.

Run: ``python benchmarks/v4x_pc_driver.py [--seconds 4] [--rounds 2]``; prints the
steps/s of each with the ratio to the baseline, the latency percentiles, and the
poller's CPU time per step (its I/O thread's; less sensitive to the machine's load).
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import serial
from cobs import cobs

from maglev_ros.hardware import v4x_pc_protocol as proto
from maglev_ros.hardware.serial_link import Backoff, LinkError
from maglev_ros.hardware.v4x_pc_link import V4xPcLink
from maglev_ros.hardware.v4x_pc_poller import REPLY_TIMEOUT_S, V4xPcPoller

CPU_PER_STEP: dict[float, list[float]] = {}  # poll rate -> I/O thread CPU s per step, per run


class _Log:
    def info(self, text, **_):
        pass

    warning = error = info


def _command(field_t: np.ndarray) -> np.ndarray:
    """Answer a field (T) with PWM counts as pairs, PD-like (small, stays in range)."""
    p_x = int(np.clip(round(field_t[0] * 1e5), -50, 50))
    p_y = int(np.clip(round(field_t[1] * 1e5), -50, 50))
    return np.array([p_x, -p_x, p_y, -p_y])


def baseline(port: str, seconds: float) -> tuple[float, np.ndarray]:
    """Run the lab host's loop: steps/s and latencies (ns) reply -> 03 written."""
    latencies = []
    with serial.Serial(port, 115200, timeout=1.0) as ser:

        def transact(payload: bytes) -> tuple[bytes, int]:
            ser.reset_input_buffer()
            ser.write(cobs.encode(payload) + b'\x00')
            ser.flush()
            reply = ser.read_until(b'\x00')
            return cobs.decode(reply[:-1]), time.time_ns()

        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            reply, stamp = transact(bytes([proto.READ_SENSORS]))
            field = np.array(proto.decode_reply(reply, proto.READ_SENSORS).field_mT) * 1e-3
            c = _command(field)
            frame = bytes([proto.SET_PWM, max(0, c[0]), max(0, -c[2]), max(0, -c[0])])
            frame += bytes([max(0, c[2])])
            latencies.append(time.time_ns() - stamp)
            transact(frame)
        transact(bytes([proto.RESET]))
    return len(latencies) / seconds, np.array(latencies)


def poller(port: str, seconds: float, rate: float) -> tuple[float, np.ndarray]:
    """Run the driver's loop with a controller in the I/O thread: steps/s, latencies (ns)."""
    link = V4xPcLink(port, timeout=REPLY_TIMEOUT_S)
    loop = V4xPcPoller(link, Backoff(0.1, 1.0), _Log(), poll_rate=rate)
    loop.open()
    stamps = []

    def answer(stamp, values):
        stamps.append(int(stamp[0]))
        loop.send(_command(values[0, :3]))

    stop = threading.Event()
    cpu = []

    def run():
        start = time.thread_time()
        loop.run(stop, answer)
        cpu.append(time.thread_time() - start)

    thread = threading.Thread(target=run)
    thread.start()
    time.sleep(seconds)
    stop.set()
    thread.join()
    loop.close()
    if loop.counts['io_errors']:
        print(f'  poller {rate:g} Hz: {loop.counts["io_errors"]} link errors ({loop.last_info})')
    s = np.array(stamps)
    CPU_PER_STEP.setdefault(rate, []).append(cpu[0] / len(s))
    return (len(s) - 1) / ((s[-1] - s[0]) * 1e-9), np.array(loop.latencies_ns)


def cycle_loop(port: str, seconds: float) -> tuple[float, np.ndarray]:
    """Run ``V4xPcLink.cycle`` back to back, nothing else: the link's own steps/s."""
    with V4xPcLink(port) as link:
        n, errors, end = 0, 0, time.perf_counter() + seconds
        while time.perf_counter() < end:
            try:
                link.cycle(0, 0)
            except LinkError as err:  # a late reply on the loaded machine: counted
                errors += 1
                print(f'  cycle loop: {err}')
                continue
            n += 1
    return n / seconds, np.empty(0)


def driver_node(port: str, seconds: float) -> tuple[float, np.ndarray]:
    """DriverNode at 1000 Hz and a controller node over DDS: steps/s, latencies (ns)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState, MagneticField

    from maglev_ros.nodes.driver import DriverNode
    from maglev_ros.nodes.messages import command_message, stamp_ns
    from maglev_ros.nodes.runtime import Spinner

    ctx = Context()
    rclpy.init(context=ctx, domain_id=97)
    params = [
        Parameter('port', value=port),
        Parameter('firmware', value='v4x_pc'),
        Parameter('start_enabled', value=True),
        Parameter('command_timeout', value=1.0),
    ]
    driver = DriverNode(context=ctx, parameter_overrides=params)
    peer = rclpy.create_node('bench_controller', context=ctx)
    pub = peer.create_publisher(JointState, 'maglev/currents/command', 10)
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    latest = {}

    def on_field(msg):
        latest['field'] = msg

    peer.create_subscription(MagneticField, 'maglev/sensor_0/field', on_field, qos)

    def on_currents(msg):
        f = latest.get('field')
        if f is None:
            return
        c = _command(np.array([f.magnetic_field.x, f.magnetic_field.y, 0.0])) / 85.0
        pub.publish(command_message(stamp_ns(f), c))

    peer.create_subscription(JointState, 'maglev/currents', on_currents, qos)
    spinner = Spinner(ctx, [driver, peer])
    time.sleep(1.0)  # discovery
    driver.session.link.latencies_ns.clear()
    start, records = time.monotonic(), driver.counters['records']
    time.sleep(seconds)
    rate = (driver.counters['records'] - records) / (time.monotonic() - start)
    latencies = np.array(driver.session.link.latencies_ns)
    spinner.close()
    driver.destroy_node()
    peer.destroy_node()
    rclpy.try_shutdown(context=ctx)
    return rate, latencies


def driver_process(port: str, seconds: float) -> tuple[float, np.ndarray]:
    """Run ``python -m maglev_ros.nodes.driver`` (v4x_pc, 1000 Hz) alone: its steps/s.

    Read from its ``/diagnostics`` (``records/s`` over each 1 s period, median), by a
    listener in this process; no controller (commands do not change the step).
    """
    import os

    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    domain = 96
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    cmd = [sys.executable, '-m', 'maglev_ros.nodes.driver', '--ros-args', '-p', f'port:={port}']
    cmd += ['-p', 'firmware:=v4x_pc', '-p', 'diagnostics_period:=1.0']
    child = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node('bench_diagnostics', context=ctx)
    rates = []

    def on_diagnostics(msg):
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if values.get('link state') == 'connected' and 'records/s' in values:
                rates.append(float(values['records/s']))

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    deadline = time.monotonic() + 30.0
    while len(rates) < 2 and time.monotonic() < deadline:  # connected, first full period
        executor.spin_once(timeout_sec=0.1)
    rates.clear()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    child.send_signal(signal.SIGINT)
    child.wait(timeout=15)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
    return float(np.median(rates)) if rates else 0.0, np.empty(0)


def _ms(latencies: np.ndarray) -> str:
    if not latencies.size:
        return 'no commands'
    p50, p90, p99 = np.percentile(latencies * 1e-6, [50, 90, 99])
    return f'latency ms p50 {p50:.3f} p90 {p90:.3f} p99 {p99:.3f}'


def main() -> None:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=4.0, help='per measurement')
    parser.add_argument('--rounds', type=int, default=2, help='alternating rounds')
    args = parser.parse_args()
    cmd = [sys.executable, '-m', 'maglev_ros.cli.virtual_board', '--firmware', 'v4x_pc']
    cmd += ['--magnet', 'fixed']
    board = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    names = ('baseline', 'cycle loop', 'poller 1000 Hz', 'poller free', 'driver node')
    names += ('driver process',)
    runs = {name: [] for name in names}
    try:
        port = board.stdout.readline().strip()
        with V4xPcLink(port, open_timeout=60.0):  # waits for the board's set-up
            pass
        for _ in range(args.rounds):
            runs['baseline'].append(baseline(port, args.seconds))
            runs['cycle loop'].append(cycle_loop(port, args.seconds))
            runs['poller 1000 Hz'].append(poller(port, args.seconds, 1000.0))
            runs['poller free'].append(poller(port, args.seconds, 0.0))
            runs['driver node'].append(driver_node(port, args.seconds))
            runs['driver process'].append(driver_process(port, args.seconds))
    finally:
        board.terminate()
        board.wait(timeout=10)
    base = np.median([r for r, _ in runs['baseline']])
    for name, results in runs.items():
        rates = [r for r, _ in results]
        lat = np.concatenate([x for _, x in results]).astype(float)
        print(
            f'{name:15s} {np.median(rates):6.0f} steps/s ({np.median(rates) / base:.2f}x '
            f'baseline; runs {", ".join(f"{r:.0f}" for r in rates)}); {_ms(lat)}'
        )
    for rate, per_step in CPU_PER_STEP.items():
        name = f'{rate:g} Hz' if rate else 'free'
        print(f'poller {name}: I/O thread CPU per step {np.median(per_step) * 1e6:.0f} us')


if __name__ == '__main__':
    main()
