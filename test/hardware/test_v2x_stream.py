import numpy as np
import pytest

from maglev_ros.hardware.v2x_stream import (
    PlausibilityBounds,
    RecordBatch,
    RecordDecoder,
    pack_records,
    record_dtype,
    record_size,
)

WRAP = 1 << 32


def make_records(n, n_sensors=1, start_us=1_000_000, seed=0, step=200):
    rng = np.random.default_rng(seed)
    stamps = start_us + step * np.arange(n, dtype=np.int64)
    field = rng.normal(0.0, 30.0, size=(n, n_sensors, 3)).astype(np.float32)
    pwm = rng.integers(-4096, 4097, size=(n, 4)).astype(np.int16)
    return stamps, field, pwm


def record_bytes(stamps, field, pwm):
    return [
        pack_records(stamps[i : i + 1], field[i : i + 1], pwm[i : i + 1])
        for i in range(len(stamps))
    ]


def decode_all(decoder, stream, chunk_sizes=None, seed=1):
    rng = np.random.default_rng(seed)
    batches = []
    i = 0
    while i < len(stream):
        size = int(rng.integers(1, 300)) if chunk_sizes is None else chunk_sizes
        batches.append(decoder.feed(stream[i : i + size]))
        i += size
    batches.append(decoder.flush())
    return RecordBatch(
        np.concatenate([b.time_us for b in batches]),
        np.concatenate([b.field_mT for b in batches]),
        np.concatenate([b.pwm for b in batches]),
    )


def assert_records(batch, stamps, field, pwm, index):
    index = np.asarray(index)
    assert len(batch) == len(index)
    np.testing.assert_array_equal(batch.time_us % WRAP, stamps[index] % WRAP)
    np.testing.assert_array_equal(batch.field_mT, field[index])
    np.testing.assert_array_equal(batch.pwm, pwm[index])


def test_record_layout():
    assert record_size(1) == 24 and record_size(3) == 48
    assert record_dtype(3).itemsize == 48
    data = pack_records([7], np.ones((1, 1, 3)), [[1, 2, 3, 4]])
    assert data == (
        np.uint32(7).tobytes()
        + np.ones(3, '<f4').tobytes()
        + np.array([1, 2, 3, 4], '<i2').tobytes()
    )


@pytest.mark.parametrize('n_sensors', [1, 3])
@pytest.mark.parametrize('confirm', [True, False])
@pytest.mark.parametrize('chunk', [None, 1, 24, 4096])
def test_clean_stream_round_trips(n_sensors, confirm, chunk):
    stamps, field, pwm = make_records(400, n_sensors)
    decoder = RecordDecoder(n_sensors, confirm=confirm)
    batch = decode_all(decoder, pack_records(stamps, field, pwm), chunk)
    assert_records(batch, stamps, field, pwm, np.arange(400))
    np.testing.assert_array_equal(batch.time_us, stamps)
    stats = decoder.stats
    assert (stats.records, stats.dropped_bytes, stats.resyncs, stats.wraps) == (400, 0, 0, 0)
    assert stats.locked


def test_confirm_holds_back_the_newest_record():
    stamps, field, pwm = make_records(10)
    decoder = RecordDecoder(1)
    assert len(decoder.feed(pack_records(stamps, field, pwm))) == 9
    assert decoder.buffered == 24
    assert len(decoder.flush()) == 1
    eager = RecordDecoder(1, confirm=False)
    assert len(eager.feed(pack_records(stamps, field, pwm))) == 10


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_mid_burst_start_costs_only_the_partial_record(n_sensors):
    stamps, field, pwm = make_records(60, n_sensors)
    stream = pack_records(stamps, field, pwm)
    size = record_size(n_sensors)
    for offset in range(1, size):
        decoder = RecordDecoder(n_sensors)
        batch = decode_all(decoder, stream[offset:])
        assert_records(batch, stamps, field, pwm, np.arange(1, 60))
        assert decoder.stats.dropped_bytes == size - offset
        assert decoder.stats.resyncs == 0


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_garbage_between_records_costs_nothing(n_sensors):
    rng = np.random.default_rng(3)
    stamps, field, pwm = make_records(300, n_sensors)
    chunks = record_bytes(stamps, field, pwm)
    total = 0
    for at in range(5, 300, 25):
        garbage = rng.integers(0, 256, size=int(rng.integers(1, 200)), dtype=np.uint8).tobytes()
        chunks[at] = garbage + chunks[at]
        total += len(garbage)
    decoder = RecordDecoder(n_sensors)
    batch = decode_all(decoder, b''.join(chunks))
    assert_records(batch, stamps, field, pwm, np.arange(300))
    assert decoder.stats.dropped_bytes == total
    assert decoder.stats.resyncs == len(range(5, 300, 25))


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_truncated_records_cost_only_themselves(n_sensors):
    stamps, field, pwm = make_records(300, n_sensors)
    chunks = record_bytes(stamps, field, pwm)
    size = record_size(n_sensors)
    damaged = list(range(3, 300, 13))
    kept = 0
    for j, at in enumerate(damaged):
        keep = 1 + j % (size - 1)  # every cut length from 1 to size - 1
        chunks[at] = chunks[at][:keep]
        kept += keep
    decoder = RecordDecoder(n_sensors)
    batch = decode_all(decoder, b''.join(chunks))
    assert_records(batch, stamps, field, pwm, np.setdiff1d(np.arange(300), damaged))
    assert decoder.stats.dropped_bytes == kept


def test_damaged_record_contents_cost_only_that_record():
    stamps, field, pwm = make_records(100)
    field[40, 0, 1] = np.nan
    pwm[60, 2] = 5000
    field[80, 0, 0] = 1e6
    decoder = RecordDecoder(1)
    batch = decode_all(decoder, pack_records(stamps, field, pwm))
    assert_records(batch, stamps, field, pwm, np.setdiff1d(np.arange(100), [40, 60, 80]))
    assert decoder.stats.dropped_bytes == 3 * 24


@pytest.mark.parametrize('confirm', [True, False])
def test_timestamp_wrap_is_unwrapped(confirm):
    stamps, field, pwm = make_records(200, start_us=WRAP - 200 * 77 - 50)
    decoder = RecordDecoder(1, confirm=confirm)
    batch = decode_all(decoder, pack_records(stamps, field, pwm))
    assert_records(batch, stamps, field, pwm, np.arange(200))
    np.testing.assert_array_equal(batch.time_us, stamps)  # int64, past 2**32
    assert batch.time_us[-1] > WRAP
    assert decoder.stats.wraps == 1


def test_wrap_inside_damaged_region():
    stamps, field, pwm = make_records(100, start_us=WRAP - 200 * 50)
    chunks = record_bytes(stamps, field, pwm)
    chunks[49] = chunks[49][:10]
    chunks[50] = b'\x3e\x00garbage' + chunks[50]
    decoder = RecordDecoder(1)
    batch = decode_all(decoder, b''.join(chunks))
    assert_records(batch, stamps, field, pwm, np.setdiff1d(np.arange(100), [49]))
    np.testing.assert_array_equal(batch.time_us, np.delete(stamps, 49))
    assert decoder.stats.wraps == 1


def test_stall_relocks_without_loss():
    stamps, field, pwm = make_records(100)
    stamps[50:] += 50_000  # the board stalled for 50 ms
    decoder = RecordDecoder(1)
    batch = decode_all(decoder, pack_records(stamps, field, pwm))
    assert_records(batch, stamps, field, pwm, np.arange(100))
    np.testing.assert_array_equal(batch.time_us, stamps)
    assert decoder.stats.dropped_bytes == 0


def test_clock_restart_keeps_time_monotonic():
    first = make_records(50, start_us=5_000_000)
    second = make_records(50, start_us=0, seed=1)
    stream = pack_records(*first) + pack_records(*second)
    decoder = RecordDecoder(1)
    batch = decode_all(decoder, stream)
    assert len(batch) == 100
    assert np.all(np.diff(batch.time_us) == 200)
    assert decoder.stats.clock_restarts == 1


def test_garbage_only_is_dropped_and_buffer_bounded():
    rng = np.random.default_rng(5)
    decoder = RecordDecoder(3)
    for _ in range(50):
        assert len(decoder.feed(rng.integers(0, 256, 1000, dtype=np.uint8).tobytes())) == 0
        assert decoder.buffered < 5 * 4 * 48
    assert decoder.stats.records == 0
    assert decoder.stats.dropped_bytes == 50_000 - decoder.buffered
    assert not decoder.stats.locked


def test_constant_fields_do_not_lock_on_a_shifted_boundary():
    # constant fields and PWM make shifted views periodic; the step bounds must reject them
    n = 100
    stamps = 1_000_000 + 200 * np.arange(n)
    field = np.full((n, 1, 3), 12.5, np.float32)
    pwm = np.zeros((n, 4), np.int16)
    stream = pack_records(stamps, field, pwm)
    for offset in range(1, 24):
        batch = decode_all(RecordDecoder(1), stream[offset:])
        np.testing.assert_array_equal(batch.time_us, stamps[1:])


@pytest.mark.parametrize('seed', range(6))
@pytest.mark.parametrize('n_sensors', [1, 3])
def test_random_faults_cost_at_most_the_damaged_records(seed, n_sensors):
    # Faults at least 8 records apart (isolated, as on a real link), any
    # kind, any size, a mid-record start and a wrap; chunking at random.
    rng = np.random.default_rng(seed)
    n = 1500
    size = record_size(n_sensors)
    stamps, field, pwm = make_records(n, n_sensors, start_us=WRAP - 200 * 700, seed=seed)
    chunks = record_bytes(stamps, field, pwm)
    damaged = set()
    for at in range(5, n - 10, 8):
        if rng.random() < 0.5:
            continue
        at += int(rng.integers(0, 3))
        if rng.random() < 0.5:
            chunks[at] = (
                rng.integers(0, 256, int(rng.integers(1, 300)), np.uint8).tobytes() + chunks[at]
            )
        else:
            chunks[at] = chunks[at][: int(rng.integers(1, size))]
            damaged.add(at)
    start = int(rng.integers(1, size))
    decoder = RecordDecoder(n_sensors)
    batch = decode_all(decoder, b''.join(chunks)[start:], seed=seed)
    expected = np.setdiff1d(np.arange(1, n), sorted(damaged))
    assert_records(batch, stamps, field, pwm, expected)
    np.testing.assert_array_equal(batch.time_us, stamps[expected])
    assert decoder.stats.wraps == 1


def test_short_runs_between_faults_are_recovered():
    # fewer than lock_records good records between faults and at the start
    stamps, field, pwm = make_records(40, 3)
    chunks = record_bytes(stamps, field, pwm)
    rng = np.random.default_rng(0)
    chunks[2] = chunks[2][:30]  # truncated third record
    chunks[10] = rng.integers(0, 256, 78, np.uint8).tobytes() + chunks[10]
    chunks[11] = rng.integers(0, 256, 61, np.uint8).tobytes() + chunks[11]  # 10 alone
    chunks[13] = chunks[13][:5]  # 11, 12 between faults
    batch = decode_all(RecordDecoder(3), b''.join(chunks))
    assert_records(batch, stamps, field, pwm, np.setdiff1d(np.arange(40), [2, 13]))


def test_bounds_validation():
    with pytest.raises(ValueError, match='lock_records must be >= 2, got 1'):
        PlausibilityBounds(lock_records=1)
    with pytest.raises(ValueError, match='min_step_us'):
        PlausibilityBounds(min_step_us=500, max_step_us=100)
    with pytest.raises(ValueError, match='n_sensors must be >= 1, got 0'):
        RecordDecoder(0)
    with pytest.raises(TypeError, match='n_sensors must be an int'):
        RecordDecoder(1.5)


def test_reset_forgets_everything():
    stamps, field, pwm = make_records(20)
    decoder = RecordDecoder(1)
    decoder.feed(pack_records(stamps, field, pwm)[5:])
    decoder.reset()
    assert decoder.stats.records == 0 and decoder.buffered == 0 and not decoder.stats.locked


def test_long_runs_spanning_more_than_2_31_us():
    # steps of 1 s: one feed covers 3000 s (> 2**31 us) and two wraps
    bounds = PlausibilityBounds(min_step_us=500_000, max_step_us=2_000_000)
    stamps, field, pwm = make_records(3000, start_us=WRAP - 10_000_000, step=1_000_000)
    for confirm in (True, False):
        decoder = RecordDecoder(1, bounds=bounds, confirm=confirm)
        batch = decode_all(decoder, pack_records(stamps, field, pwm), chunk_sizes=1 << 20)
        np.testing.assert_array_equal(batch.time_us, stamps)
        assert decoder.stats.wraps == 1


@pytest.mark.parametrize('n_sensors', [1, 3])
@pytest.mark.parametrize('lost', [1, 2])
@pytest.mark.parametrize('chunk', [None, 1, 4096])
def test_lost_head_bytes_cost_only_that_record(n_sensors, lost, chunk):
    """Issue 11 item 11: 40 records 200 us apart, the first bytes of record 20 lost.

    Before: record 19 (intact) was lost, record 20 stamped with 19's timestamp
    bytes (200 us early), every later record shifted by +4800 us, one clock restart.
    """
    stamps, field, pwm = make_records(40, n_sensors, start_us=0)
    parts = record_bytes(stamps, field, pwm)
    parts[20] = parts[20][lost:]
    decoder = RecordDecoder(n_sensors)
    out = decode_all(decoder, b''.join(parts), chunk_sizes=chunk)
    kept = [i for i in range(40) if i != 20]
    assert_records(out, stamps, field, pwm, kept)
    np.testing.assert_array_equal(out.time_us, stamps[kept])
    assert decoder.stats.clock_restarts == 0


# -- a corrupted link: one fault every 7 ms for 20 s of stream --------------------------


def smooth_stream(n, pwm_mode, seed):
    """Records as the board sends them: smooth fields, the PWM of the last command."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 200e-6
    stamps = 1_000_000 + 200 * np.arange(n, dtype=np.int64)
    base = np.stack(
        [2 * np.sin(2 * np.pi * 3 * t), 1.5 * np.cos(2 * np.pi * 2 * t), 40 + 3 * np.sin(t)], 1
    )
    field = (base[:, None, :] + rng.normal(0, 0.05, (n, 1, 3))).astype(np.float32)
    if pwm_mode == 'zero':  # the board applied 0
        pwm = np.zeros((n, 4), np.int16)
    else:  # a new command every 1 ms (5 records)
        commands = rng.integers(-1500, 1501, (n // 5 + 1, 4)).astype(np.int16)
        pwm = np.repeat(commands, 5, axis=0)[:n]
    return stamps, field, pwm


def corrupt(stamps, field, pwm, kind, seed, every=35):
    """Damage one record every ``every`` records (7 ms); return the stream, damaged indices."""
    rng = np.random.default_rng(seed)
    parts = record_bytes(stamps, field, pwm)
    size = len(parts[0])
    damaged = set()
    for at in range(every // 2, len(parts) - 2, every):
        if kind == 'copy':  # a partial copy of a recent record, inserted
            src = parts[at - int(rng.integers(1, 5))]
            a = int(rng.integers(0, size - 1))
            parts[at] = src[a : int(rng.integers(a + 1, size))] + parts[at]
        elif kind == 'repeat':  # the last bytes sent, sent again (up to 2 records)
            m = int(rng.integers(1, 2 * size))
            parts[at] = b''.join(parts[at - 3 : at])[-m:] + parts[at]
        elif kind == 'head':  # a record lost its first bytes
            parts[at] = parts[at][int(rng.integers(1, size)) :]
            damaged.add(at)
        elif kind == 'tail':  # a record lost its last bytes
            parts[at] = parts[at][: -int(rng.integers(1, size))]
            damaged.add(at)
    return b''.join(parts), damaged


def check_published(batch, stamps, field, pwm, damaged):
    """Every sample is one intact record, byte for byte, once and in order; return lost."""
    index = np.searchsorted(stamps, batch.time_us)
    assert np.all(index < len(stamps))
    np.testing.assert_array_equal(stamps[index], batch.time_us)  # a stamp of the stream
    np.testing.assert_array_equal(batch.field_mT, field[index])  # its own fields
    np.testing.assert_array_equal(batch.pwm, pwm[index])  # and PWM
    assert not damaged & set(index.tolist())  # no damaged record (foreign bytes)
    assert np.all(np.diff(batch.time_us) > 0)  # none twice, none out of order
    return len(stamps) - len(damaged) - len(index)


@pytest.mark.parametrize('pwm_mode', ['zero', 'commands'])
@pytest.mark.parametrize('kind', ['copy', 'repeat', 'head', 'tail'])
def test_one_fault_every_7_ms_for_20_s(kind, pwm_mode):
    n = 100_000  # 20 s at 5 kHz
    stamps, field, pwm = smooth_stream(n, pwm_mode, seed=1)
    stream, damaged = corrupt(stamps, field, pwm, kind, seed=2)
    decoder = RecordDecoder(1)
    batches = []
    for k in range(0, len(stream), 120):  # one 5-record burst per read, as the driver reads
        if pwm_mode == 'commands':
            decoder.note_command(pwm[min(k // 24, n - 1)])  # the command just sent
        batches.append(decoder.feed(stream[k : k + 120]))
    batches.append(decoder.flush())
    batch = RecordBatch(*(np.concatenate(parts) for parts in zip(*batches, strict=True)))
    lost = check_published(batch, stamps, field, pwm, damaged)
    assert lost <= 0.01 * (n - len(damaged))
    faults = len(range(17, n - 2, 35))
    assert decoder.stats.resyncs == faults  # every fault shows: 143 per second
    assert decoder.stats.dropped_bytes > 0


@pytest.mark.parametrize('low_byte', range(0, 11))
def test_record_that_lost_its_first_byte_is_never_taken(low_byte):
    # the first byte of record 20 (its timestamp's low byte) lost, the PWM all zero:
    # the held record's last byte (0) and the rest of record 20 look like a record
    stamps, field, pwm = smooth_stream(40, 'zero', seed=3)
    stamps = (stamps - stamps[20]) + (1_000_000 & ~0xFF) + low_byte
    parts = record_bytes(stamps, field, pwm)
    parts[20] = parts[20][1:]
    decoder = RecordDecoder(1)
    batch = decode_all(decoder, b''.join(parts), chunk_sizes=120)
    lost = check_published(batch, stamps, field, pwm, {20})
    assert lost <= 1  # the record before it may go too: prefer losing to a wrong sample
    if lost:
        assert decoder.stats.overlaps == 1
