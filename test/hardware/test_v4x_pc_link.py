"""The V4x PC-control link against the emulated board on a real pty."""

import threading
import time
from functools import partial

import numpy as np
import pytest

from maglev_ros.hardware import v4x_pc_protocol as p
from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.serial_link import LinkError
from maglev_ros.hardware.v4x_pc_firmware import V4xPcFirmware, adc_current
from maglev_ros.hardware.v4x_pc_link import ReplyTimeoutError, V4xPcLink
from maglev_ros.hardware.virtual_board import VirtualBoard

SCALING = CurrentScaling.from_supply(12.0, 4.0, full_scale=255)
TIMEOUT = 20.0  # s, generous: the machine is shared


class NoisyPlant:
    """A static field with noise: no two readings are equal (no freeze resets)."""

    def __init__(self):
        self.rng = np.random.default_rng(3)

    def __call__(self, pwm, t):
        field = np.array([0.5, -0.3, 40.0]) + 0.01 * np.asarray(pwm, float)[[0, 2, 1]]
        return (field + self.rng.normal(0.0, 0.01, 3))[None, :]


@pytest.fixture(scope='module')
def board():
    factory = lambda: V4xPcFirmware(NoisyPlant(), scaling=SCALING, init_delay=0.0).power_up()  # noqa: E731
    with VirtualBoard(factory) as vb:
        assert vb.wait_until(lambda b: b.firmware.running, TIMEOUT)
        yield vb


def fw_state(board, attr):
    with board.lock:
        value = getattr(board.firmware, attr)
        return value.copy() if hasattr(value, 'copy') else value


def test_every_pwm_difference_reaches_the_board(board):
    with V4xPcLink(board.path, timeout=1.0) as link:
        for pair in (0, 1):
            for diff in range(-255, 256):
                link.command(diff, 0) if pair == 0 else link.command(0, diff)
                pwm = fw_state(board, 'pwm')
                expected = [diff, -diff, 0, 0] if pair == 0 else [0, 0, diff, -diff]
                assert pwm.tolist() == expected
        assert link.counts.requests == 2 * 511 + 1  # and the reset of open
        assert link.counts.resyncs == 1  # the one of open


def test_a_request_is_answered_when_it_arrives_not_when_the_board_last_ran(board):
    """The pacing runs the board's samples up to now before it hands over the host's bytes.

    Handed over first, a request that came while the pacing thread waited (or
    was descheduled) was answered from the sample of the thread's previous
    pass and its command applied from then: up to a whole wait earlier than it
    was sent, on the board's clock. Here the wait is a pause of 0.1 s.
    """
    with V4xPcLink(board.path, timeout=TIMEOUT) as link:
        board.pause()
        with board.lock:
            paused_at = board.firmware.now_us
        resume = threading.Timer(0.1, board.resume)
        resume.start()
        try:
            time.sleep(0.05)
            link.command(40, 0)  # waits for the board to come back
        finally:
            resume.join()
        with board.lock:
            applied_us, p_x, _ = board.firmware.applied[-1]
    assert p_x == 40
    assert applied_us - paused_at >= 100_000  # us: when the board took it, after the pause


def test_fields_and_currents_in_our_order(board):
    with V4xPcLink(board.path, timeout=1.0) as link:
        link.command(85, -170)  # 1 A on x+, -2 A on y+
        currents = link.read_currents()
        np.testing.assert_array_equal(
            currents, adc_current(np.array([1.0, -1.0, -2.0, 2.0])).astype(float)
        )
        field, rate = link.read_sensors()
        with board.lock:
            sent = [r for r in board.firmware.replies if r[0] == p.READ_SENSORS][-1]
        reply = p.decode_reply(sent, p.READ_SENSORS)
        np.testing.assert_array_equal(field, reply.field_mT)
        assert rate[2] == 0.0
        status = link.status()
        assert status.solenoids == 4 and status.sensors == 9 and status.uptime_s >= 3


def test_close_resets_the_coils(board):
    with V4xPcLink(board.path, timeout=1.0) as link:
        link.command(-100, 50)
        assert fw_state(board, 'pwm').tolist() == [-100, 100, 50, -50]
    assert fw_state(board, 'pwm').tolist() == [0, 0, 0, 0]


def test_close_on_an_exception_resets_the_coils(board):
    with pytest.raises(RuntimeError, match='controller failed'):
        with V4xPcLink(board.path, timeout=1.0) as link:
            link.command(120, 0)
            raise RuntimeError('controller failed')
    assert fw_state(board, 'pwm').tolist() == [0, 0, 0, 0]


def test_timeout_resets_the_coils(board):
    with V4xPcLink(board.path, timeout=0.05) as link:
        link.command(77, 33)
        board.pause()  # the board stops answering for 0.3 s
        resume = threading.Timer(0.3, board.resume)
        resume.start()
        try:
            with pytest.raises(ReplyTimeoutError, match='no reply to request 01 within 0.05 s'):
                link.read_sensors()
        finally:
            resume.join()
        assert board.wait_until(lambda b: b.firmware.pwm.tolist() == [0, 0, 0, 0], TIMEOUT)
        assert link.counts.timeouts == 1
        link.command(5, 5)  # the link works again
        assert fw_state(board, 'pwm').tolist() == [5, -5, 5, -5]


def test_half_frame_from_the_host_is_recovered(board):
    with V4xPcLink(board.path, timeout=0.2) as link:
        link.command(60, 0)
        link._serial.write(b'\x03\x05\x10')  # a request cut short on the way
        with pytest.raises(LinkError, match='reply 05 04 09 .* does not answer request 0x01'):
            link.read_sensors()  # merged with the half frame: a status reply comes
        assert fw_state(board, 'pwm').tolist() == [0, 0, 0, 0]  # reset after the error
        field, _ = link.read_sensors()
        assert np.all(np.isfinite(field))


def test_garbage_towards_the_host_never_gives_a_wrong_value(board):
    rng = np.random.default_rng(11)
    garbage = rng.integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
    values, errors = 0, 0
    chunk = 16384
    with V4xPcLink(board.path, timeout=0.2) as link:
        for k in range(0, len(garbage), chunk):
            board.inject(garbage[k : k + chunk])
            for _ in range(3):
                try:
                    field, _ = link.read_sensors()
                except LinkError:
                    errors += 1
                    continue
                with board.lock:
                    sent = {r for r in board.firmware.replies if r[0] == p.READ_SENSORS}
                assert p.sensors_payload(field, _)[1:13] in {r[1:13] for r in sent}
                values += 1
        counts = link.counts
    assert values >= 64  # the link recovers after every chunk
    assert errors >= 1 and counts.resyncs > 1 and counts.dropped_bytes >= len(garbage) // 2
    print(f'values {values}, errors {errors}, counts {counts}')


def test_no_answer_to_the_ping_names_port_and_firmware():
    factory = partial(V2xFirmware, LinearPlant.default(1), 1, startup_delay=0.1)
    with VirtualBoard(factory) as v2x:
        link = V4xPcLink(v2x.path, open_timeout=0.5)
        with pytest.raises(LinkError, match=f'{v2x.path}: no answer to the ping .*V4x PC-control'):
            link.open()
        assert not link.is_open


def test_missing_port():
    with pytest.raises(LinkError, match='cannot open /nonexistent/ttyACM9'):
        V4xPcLink('/nonexistent/ttyACM9').open()


def test_a_megabyte_of_garbage_and_half_frames_towards_the_board(board):
    import serial

    rng = np.random.default_rng(12)
    garbage = rng.integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
    with serial.Serial(board.path, 115200, timeout=0.01) as port:
        for k in range(0, len(garbage), 8192):
            port.write(garbage[k : k + 8192])
            port.read(1 << 16)  # the board answers what it took for requests
        port.write(b'\x02\x01')  # and a half frame at the end
    with board.lock:
        fw = board.firmware
        executed = sum(count for code, count in fw.requests.items() if code != 0x100)
        assert executed > 1000 and fw.errors_sent > 0 and fw.split_frames > 0
    with V4xPcLink(board.path, timeout=0.5) as link:  # resynchronises, resets the coils
        assert fw_state(board, 'pwm').tolist() == [0, 0, 0, 0]
        link.command(10, -10)
        field, _ = link.read_sensors()
        with board.lock:
            sent = [r for r in board.firmware.replies if r[0] == p.READ_SENSORS][-1]
        np.testing.assert_array_equal(field, p.decode_reply(sent, p.READ_SENSORS).field_mT)
        assert fw_state(board, 'pwm').tolist() == [10, -10, -10, 10]
        assert link.counts.resyncs == 1
    board.check()  # the emulator thread did not fail


def test_unplug_gives_a_link_error_and_close_still_works():
    factory = lambda: V4xPcFirmware(NoisyPlant(), scaling=SCALING, init_delay=0.0).power_up()  # noqa: E731
    with VirtualBoard(factory) as vb:
        assert vb.wait_until(lambda b: b.firmware.running, TIMEOUT)
        link = V4xPcLink(vb.path, timeout=0.2).open()
        link.command(30, 30)
        vb.unplug()
        with pytest.raises(LinkError, match=vb.path):
            for _ in range(3):  # the first request may still see the closing pty
                link.read_sensors()
        link.close()  # best effort reset on a port that is gone: no exception
        assert not link.is_open


def test_cycle_reads_and_commands_in_one_round_trip(board):
    with V4xPcLink(board.path, timeout=1.0) as link:
        link.command(85, 0)
        before = time.time_ns()
        step = link.cycle(-170, 42)
        assert before < step.stamp_ns < time.time_ns()
        # the currents are read before the command is applied: the previous one's
        expected = adc_current(np.array([1.0, -1.0, 0.0, 0.0])).astype(float)
        np.testing.assert_array_equal(step.currents_A, expected)
        with board.lock:
            sent = [r for r in board.firmware.replies if r[0] == p.READ_SENSORS][-1]
        np.testing.assert_array_equal(step.field_mT, p.decode_reply(sent, 1).field_mT)
        assert fw_state(board, 'pwm').tolist() == [-170, 170, 42, -42]
        requests = link.counts.requests
        for k in range(200):
            link.cycle(k - 100, 100 - k)
        assert link.counts.requests == requests + 600 and link.counts.resyncs == 1
        assert fw_state(board, 'pwm').tolist() == [99, -99, -99, 99]


def test_a_streaming_board_of_another_firmware_fails_the_ping_in_time():
    """A V2x board never falls quiet: the drain must still end at the open deadline."""
    with VirtualBoard(partial(V2xFirmware, LinearPlant.default(1), 1, startup_delay=0.0)) as vb:
        link = V4xPcLink(vb.path, open_timeout=0.5)
        start = time.monotonic()
        with pytest.raises(LinkError, match=f'{vb.path}: no answer to the ping .* V4x PC-control'):
            link.open()
        assert time.monotonic() - start < 5.0
        assert not link.is_open
