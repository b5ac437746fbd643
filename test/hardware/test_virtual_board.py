import os
import time
from functools import partial

import numpy as np
import pytest
import serial

from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware, V4xFirmware
from maglev_ros.hardware.packet import encode_command, sendable_pwm
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.v2x_stream import RecordDecoder, record_size
from maglev_ros.hardware.v4x_telemetry import InfoMessage, TelemetrySample, TelemetryStream
from maglev_ros.hardware.virtual_board import VirtualBoard, VirtualBoardError

TIMEOUT = 10.0  # s, generous: the machine is shared


def v2x(n_sensors=1, **kwargs):
    kwargs.setdefault('startup_delay', 0.1)
    return partial(V2xFirmware, LinearPlant.default(n_sensors), n_sensors, **kwargs)


def read_records(port, decoder, count, timeout=TIMEOUT):
    batches = []
    total = 0
    deadline = time.monotonic() + timeout
    while total < count:
        assert time.monotonic() < deadline, f'only {total} of {count} records arrived'
        batch = decoder.feed(port.read(max(1, port.in_waiting)))
        if len(batch):
            batches.append(batch)
            total += len(batch)
    return (
        np.concatenate([b.time_us for b in batches]),
        np.concatenate([b.field_mT for b in batches]),
        np.concatenate([b.pwm for b in batches]),
    )


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_host_reads_the_plant_fields(n_sensors):
    plant = LinearPlant.default(n_sensors)
    factory = partial(V2xFirmware, plant, n_sensors, startup_delay=0.1)
    with VirtualBoard(factory) as board, serial.Serial(board.path, 9600, timeout=0.05) as port:
        assert os.path.realpath(board.path) == board.device
        port.write(encode_command([300, -300, 1000, -4096]))
        decoder = RecordDecoder(n_sensors)
        time_us, field, pwm = read_records(port, decoder, 300)
        assert np.all(np.diff(time_us) == 200)
        assert decoder.stats.dropped_bytes == 0
        expected = np.stack([plant(p, 0.0) for p in pwm]).astype(np.float32)
        np.testing.assert_array_equal(field, expected)
        assert {tuple(p) for p in pwm} <= {(0, 0, 0, 0), (300, -300, 1000, -4096)}
        assert tuple(pwm[-1]) == (300, -300, 1000, -4096)
        assert board.status.port_opens == 1


def test_current_sweep_reaches_the_board_as_scaled_pwm():
    scaling = CurrentScaling.from_supply(supply_voltage=12.0, coil_resistance=3.0)
    amps = np.linspace(-1.05 * scaling.max_current, 1.05 * scaling.max_current, 9001)
    counts = scaling.to_counts(amps)
    assert set(range(-4096, 4097)) <= set(counts.tolist())  # the whole PWM range
    commands = np.stack([counts, -counts, np.roll(counts, 1), np.roll(counts, 2)], axis=1)
    with VirtualBoard(v2x()) as board, serial.Serial(board.path, 9600, timeout=0.05) as port:
        port.write(b''.join(encode_command(c) for c in commands))
        port.flush()
        assert board.wait_until(lambda b: len(b.firmware.accepted) >= len(commands), TIMEOUT)
        with board.lock:
            accepted = np.array([pwm for _, pwm in board.firmware.accepted])
            discarded = board.firmware.parser.discarded
    assert discarded == 0
    np.testing.assert_array_equal(accepted, sendable_pwm(commands))
    assert np.abs(accepted - commands).max() == 1  # only where the exact value cannot pass


def test_watchdog_zeroes_the_coils_when_commands_stop():
    with (
        VirtualBoard(v2x(watchdog=0.3)) as board,
        serial.Serial(board.path, 9600, timeout=0.05) as port,
    ):
        port.write(encode_command([800, 800, -800, -800]))
        assert board.wait_until(lambda b: list(b.firmware.pwm) == [800, 800, -800, -800], TIMEOUT)
        assert board.wait_until(lambda b: b.firmware.watchdog_trips == 1, TIMEOUT)
        # the records (queued while we were not reading) show the PWM applied, then zeroed
        decoder = RecordDecoder(1)
        seen = []
        deadline = time.monotonic() + TIMEOUT
        while not (seen and np.any(np.concatenate(seen)[:, 0] == 800) and seen[-1][-1, 0] == 0):
            assert time.monotonic() < deadline, 'the zeroing never showed in the records'
            seen.append(read_records(port, decoder, 50)[2])
        pwm = np.concatenate(seen)
        last_on = np.flatnonzero(pwm[:, 0] == 800)[-1]
        np.testing.assert_array_equal(pwm[last_on + 1 :], 0)  # zero ever after


def test_unplug_and_replug_keep_the_path():
    with VirtualBoard(v2x()) as board:
        path = board.path
        first_device = board.device
        port = serial.Serial(path, 9600, timeout=0.05)
        read_records(port, RecordDecoder(1), 10)
        board.unplug()
        assert not os.path.lexists(path)
        with pytest.raises(serial.SerialException):
            for _ in range(100):
                port.read(100)
        port.close()
        with pytest.raises(serial.SerialException):
            serial.Serial(path, 9600)
        board.plug()
        assert os.path.realpath(path) == board.device != first_device or board.device
        with serial.Serial(path, 9600, timeout=0.05) as port:
            time_us, _, _ = read_records(port, RecordDecoder(1), 10)
        assert board.status.plugs == 2 and board.status.port_opens == 2
        assert time_us[0] < 1_000_000  # a fresh power-up: the clock restarted


def test_port_reopen_is_detected():
    with VirtualBoard(v2x()) as board:
        for _ in range(2):
            with serial.Serial(board.path, 9600, timeout=0.05) as port:
                read_records(port, RecordDecoder(1), 5)
            assert board.wait_until(lambda b: not b.status.port_open, TIMEOUT)
        assert board.status.port_opens == 2


def test_nothing_written_before_the_host_opened_reaches_it():
    """An open restarts the V2x start-up delay: no byte comes before it ends."""
    with VirtualBoard(v2x(startup_delay=0.5)) as board:
        time.sleep(0.8)  # the board streams into the closed port meanwhile
        with serial.Serial(board.path, 9600, timeout=0.05) as port:
            opened = time.monotonic()
            first = b''
            while not first and time.monotonic() - opened < TIMEOUT:
                first = port.read(1)
            waited = time.monotonic() - opened
    assert first and waited >= 0.45, waited


def test_faults_over_the_pty_cost_only_damaged_records():
    clock_start = (1 << 32) - 700_000  # wraps about 0.6 s after the data starts
    with VirtualBoard(v2x(clock_start_us=clock_start)) as board:
        with serial.Serial(board.path, 9600, timeout=0.05) as port:
            size = record_size(1)
            board.tamper_next_burst(lambda b: b[7:])  # mid-burst start: record 0 partial
            decoder = RecordDecoder(1)
            times = [read_records(port, decoder, 20)[0]]
            garbage = b'\x3e\x3c garbage \xff\x00' * 3
            board.inject(garbage)
            board.tamper_next_burst(lambda b: b[: 2 * size + 5] + b[3 * size :])  # truncated
            while decoder.stats.wraps == 0 or len(times) < 10:
                times.append(read_records(port, decoder, 100)[0])
            status = board.status
    stats = decoder.stats
    all_t = np.concatenate(times)
    assert status.bytes_dropped == 0  # the host kept up: every fault is ours
    assert stats.wraps == 1 and np.all(np.diff(all_t) > 0)
    assert stats.dropped_bytes == (size - 7) + len(garbage) + 5
    # exactly one record (the truncated one) is missing from the sequence
    assert np.count_nonzero(np.diff(all_t) == 400) == 1
    assert np.all(np.isin(np.diff(all_t), [200, 400]))


def test_v4x_telemetry_over_the_pty():
    factory = partial(V4xFirmware, LinearPlant.default(2), 2, log_period=0.002, startup_delay=0.1)
    with VirtualBoard(factory) as board, serial.Serial(board.path, 115200, timeout=0.05) as port:
        stream = TelemetryStream(2)
        items = []
        deadline = time.monotonic() + TIMEOUT
        while sum(isinstance(i, TelemetrySample) for i in items) < 20:
            assert time.monotonic() < deadline
            items += stream.feed(port.read(max(1, port.in_waiting)))
            if len(items) > 10 and not any(
                isinstance(i, InfoMessage) and 'freeze' in i.text for i in items
            ):
                with board.lock:
                    board.firmware.inject_freeze()
        infos = [i.text for i in items if isinstance(i, InfoMessage)]
        assert infos[:4] == [
            'Sensor on channel 0 initialized successfully.',
            'Sensor on channel 1 initialized successfully.',
            'Calibrating sensors...',
            'Sensor calibration complete.',
        ]
        assert 'Sensor freeze detected! Resetting...' in infos
        assert stream.stats.malformed == 0


def test_close_removes_link_and_is_idempotent(tmp_path):
    link = tmp_path / 'ttyMAGGY7'
    board = VirtualBoard(v2x(), link=link).open()
    assert link.is_symlink()
    board.close()
    board.close()
    assert not os.path.lexists(link)


def test_bad_arguments(tmp_path):
    with pytest.raises(VirtualBoardError, match='link directory does not exist'):
        VirtualBoard(v2x(), link=tmp_path / 'missing' / 'tty')
    (tmp_path / 'file').write_text('keep me')
    with pytest.raises(VirtualBoardError, match='link exists and is not a symlink'):
        VirtualBoard(v2x(), link=tmp_path / 'file')
    with pytest.raises(VirtualBoardError, match='firmware_factory must be callable, got int'):
        VirtualBoard(3)
    with pytest.raises(VirtualBoardError, match='not open'):
        _ = VirtualBoard(v2x()).path
