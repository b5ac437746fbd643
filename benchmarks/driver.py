"""Benchmark of the board driver's hot paths.

Decoder: ``RecordDecoder`` against a naive decoder that walks the same clean
V2x stream record by record with ``struct.unpack_from``, checks the same
invariants (timestamp step, field bound, PWM range), unwraps the timestamps
and builds the same arrays. Both run in this process on the same bytes;
the outputs are compared. The plain unpack loop without checks is shown
too, as a floor for any per-record Python decoder.

Run: ``/tmp/venv/bin/python benchmarks/driver.py [--quick]``.
"""

from __future__ import annotations

import argparse
import struct
import time

import numpy as np

from maglev_ros.hardware.v2x_stream import (
    BURST_RECORDS,
    PlausibilityBounds,
    RecordDecoder,
    pack_records,
    record_size,
)


def make_stream(n_records: int, n_sensors: int) -> bytes:
    """Clean stream starting near the uint32 wrap, random fields and PWM."""
    rng = np.random.default_rng(0)
    stamps = (1 << 32) - 100 * 200 + 200 * np.arange(n_records, dtype=np.int64)
    field = rng.normal(0.0, 30.0, size=(n_records, n_sensors, 3))
    pwm = rng.integers(-4096, 4097, size=(n_records, 4))
    return pack_records(stamps, field, pwm)


def naive_decode(data: bytes, n_sensors: int, bounds: PlausibilityBounds):
    """Per-record struct.unpack decoder for an aligned stream (same checks)."""
    fmt = struct.Struct(f'<I{3 * n_sensors}f4h')
    size = fmt.size
    n_field = 3 * n_sensors
    times, fields, pwms = [], [], []
    last_raw = None
    time_us = 0
    for offset in range(0, len(data) - size + 1, size):
        values = fmt.unpack_from(data, offset)
        raw = values[0]
        field = values[1 : 1 + n_field]
        pwm = values[1 + n_field :]
        if last_raw is None:
            time_us = raw
        else:
            step = (raw - last_raw) & 0xFFFF_FFFF
            if not bounds.min_step_us <= step <= bounds.max_step_us:
                raise ValueError(f'bad step at byte {offset}')
            time_us += step
        if not all(abs(b) <= bounds.max_field_mT for b in field):
            raise ValueError(f'bad field at byte {offset}')
        if not all(-4096 <= p <= 4096 for p in pwm):
            raise ValueError(f'bad PWM at byte {offset}')
        last_raw = raw
        times.append(time_us)
        fields.append(field)
        pwms.append(pwm)
    return (
        np.array(times, dtype=np.int64),
        np.array(fields, dtype=np.float32).reshape(-1, n_sensors, 3),
        np.array(pwms, dtype=np.int16),
    )


def bare_unpack(data: bytes, n_sensors: int) -> list:
    """Only unpack each record (no checks, no arrays): a floor."""
    fmt = struct.Struct(f'<I{3 * n_sensors}f4h')
    return [fmt.unpack_from(data, off) for off in range(0, len(data) - fmt.size + 1, fmt.size)]


def vector_decode(data: bytes, n_sensors: int, chunk: int):
    decoder = RecordDecoder(n_sensors)
    batches = [decoder.feed(data[i : i + chunk]) for i in range(0, len(data), chunk)]
    batches.append(decoder.flush())
    return (
        np.concatenate([b.time_us for b in batches]),
        np.concatenate([b.field_mT for b in batches]),
        np.concatenate([b.pwm for b in batches]),
    )


def best_time(repeats: int, fn, *args) -> float:
    best = float('inf')
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best


def bench_decoder(n_records: int, repeats: int) -> None:
    print(f'## Decoder throughput (records per second, best of {repeats})')
    print()
    print('| sensors | feed size | naive unpack+checks | bare unpack | RecordDecoder | speed-up |')
    print('|---|---|---|---|---|---|')
    bounds = PlausibilityBounds()
    for n_sensors in (1, 3):
        data = make_stream(n_records, n_sensors)
        expected = naive_decode(data, n_sensors, bounds)
        t_naive = best_time(repeats, naive_decode, data, n_sensors, bounds)
        t_bare = best_time(repeats, bare_unpack, data, n_sensors)
        burst = BURST_RECORDS * record_size(n_sensors)
        for chunk, label in ((65536, '64 KiB'), (burst, f'1 burst ({burst} B)')):
            got = vector_decode(data, n_sensors, chunk)
            for a, b in zip(got, expected, strict=True):
                np.testing.assert_array_equal(a, b)
            t_vec = best_time(repeats, vector_decode, data, n_sensors, chunk)
            print(
                f'| {n_sensors} | {label} | {n_records / t_naive:,.0f} | '
                f'{n_records / t_bare:,.0f} | {n_records / t_vec:,.0f} | '
                f'{t_naive / t_vec:.1f}x |'
            )
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--quick', action='store_true', help='smaller data, fewer repeats')
    args = parser.parse_args()
    n_records, repeats = (30_000, 2) if args.quick else (100_000, 3)
    bench_decoder(n_records, repeats)


if __name__ == '__main__':
    main()
