"""Benchmark: control cycles per second over the V4x PC-control link.

One cycle is what a PC-side controller does per step: read the sensors (``01``)
and command the coils (``03``), two round trips. The board is the virtual V4x
PC-control board (``maglev-virtual-board --firmware v4x_pc``, physics plant,
magnet fixed) in its own process on a pty, so the host and the emulator share
the machine's cores as a host and a real board would not (a real board answers
from its own CPU).

Measured in the same run, alternating, on the same board:

* **baseline**: pyserial as the lab's host example uses it per request
  (``reset_input_buffer``, ``write``, ``flush``, ``read_until`` up to 0x00), with the
  ``cobs`` package;
* **V4xPcLink**: this package's link (exact-frame replies, poll-based reads),
  ``read_sensors`` then ``command``: two round trips;
* **V4xPcLink.cycle**: ``01``, ``02`` and ``03`` written together, one round trip
  (reads the currents too).

Run: ``python benchmarks/v4x_pc_link.py [--seconds 5] [--rounds 3]``; prints cycles/s
of each, the ratio, and the round-trip percentiles of the link.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import numpy as np
import serial
from cobs import cobs

from maglev_ros.hardware import v4x_pc_protocol as proto
from maglev_ros.hardware.v4x_pc_link import V4xPcLink


def baseline_cycles(port: str, seconds: float) -> float:
    """Cycles/s with pyserial's read_until per request (the lab host's pattern)."""
    with serial.Serial(port, 115200, timeout=1.0) as ser:

        def transact(payload: bytes) -> bytes:
            ser.reset_input_buffer()
            ser.write(cobs.encode(payload) + b'\x00')
            ser.flush()
            return cobs.decode(ser.read_until(b'\x00')[:-1])

        cycles = 0
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            reply = transact(bytes([proto.READ_SENSORS]))
            assert reply[0] == proto.READ_SENSORS
            transact(bytes([proto.SET_PWM, 0, 0, 0, 0]))
            cycles += 1
        return cycles / seconds


def link_cycles(port: str, seconds: float) -> tuple[float, np.ndarray]:
    """Cycles/s with V4xPcLink, and each cycle's duration (s)."""
    durations = []
    with V4xPcLink(port, timeout=0.5) as link:
        end = time.perf_counter() + seconds
        while True:
            start = time.perf_counter()
            if start >= end:
                break
            link.read_sensors()
            link.command(0, 0)
            durations.append(time.perf_counter() - start)
    return len(durations) / seconds, np.array(durations)


def pipelined_cycles(port: str, seconds: float) -> tuple[float, np.ndarray]:
    """Cycles/s with V4xPcLink.cycle (01 + 02 + 03 in one write), and each cycle's duration."""
    durations = []
    with V4xPcLink(port, timeout=0.5) as link:
        end = time.perf_counter() + seconds
        while True:
            start = time.perf_counter()
            if start >= end:
                break
            link.cycle(0, 0)
            durations.append(time.perf_counter() - start)
    return len(durations) / seconds, np.array(durations)


def main() -> None:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=5.0, help='per measurement')
    parser.add_argument('--rounds', type=int, default=3, help='alternating rounds')
    args = parser.parse_args()
    cmd = [sys.executable, '-m', 'maglev_ros.cli.virtual_board', '--firmware', 'v4x_pc']
    cmd += ['--magnet', 'fixed']
    board = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    try:
        port = board.stdout.readline().strip()
        with V4xPcLink(port, open_timeout=60.0):  # waits for the board's set-up
            pass
        base, ours, piped, durations, piped_durations = [], [], [], [], []
        for _ in range(args.rounds):
            base.append(baseline_cycles(port, args.seconds))
            rate, d = link_cycles(port, args.seconds)
            ours.append(rate)
            durations.append(d)
            rate, d = pipelined_cycles(port, args.seconds)
            piped.append(rate)
            piped_durations.append(d)
    finally:
        board.terminate()
        board.wait(timeout=10)
    print(f'baseline (pyserial read_until): {np.median(base):7.0f} cycles/s  {base}')
    print(f'V4xPcLink 01 then 03:           {np.median(ours):7.0f} cycles/s  {ours}')
    print(f'V4xPcLink.cycle 01+02+03:       {np.median(piped):7.0f} cycles/s  {piped}')
    print(f'ratio (median) link: {np.median(ours) / np.median(base):.2f}x')
    print(f'ratio (median) cycle: {np.median(piped) / np.median(base):.2f}x')
    for name, runs in (('01 then 03', durations), ('cycle', piped_durations)):
        d = np.concatenate(runs) * 1e3
        print(
            f'{name} ms: median {{:.3f}}, p90 {{:.3f}}, p99 {{:.3f}}, max {{:.3f}}'.format(
                *np.percentile(d, [50, 90, 99, 100])
            )
        )


if __name__ == '__main__':
    main()
