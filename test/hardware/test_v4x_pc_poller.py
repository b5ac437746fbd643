"""The driver's V4x PC-control loop against the emulated board on a real pty (no ROS)."""

import threading
import time

import numpy as np
import pytest

from maglev_ros.hardware import v4x_pc_protocol as proto
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.serial_link import Backoff
from maglev_ros.hardware.v4x_pc_firmware import V4xPcFirmware, adc_current
from maglev_ros.hardware.v4x_pc_link import V4xPcLink
from maglev_ros.hardware.v4x_pc_poller import REPLY_TIMEOUT_S, V4xPcPoller
from maglev_ros.hardware.virtual_board import VirtualBoard

SCALING = CurrentScaling.from_supply(12.0, 4.0, full_scale=255)
TIMEOUT = 20.0  # s, generous: the machine is shared


class Log:
    def __init__(self):
        self.lines = []

    def info(self, text, **_):
        self.lines.append(('info', text))

    def warning(self, text, **_):
        self.lines.append(('warning', text))

    def error(self, text, **_):
        self.lines.append(('error', text))


RNG = np.random.default_rng(9)


def noisy(pwm, t):
    return (np.array([0.5, -0.3, 40.0]) + RNG.normal(0.0, 0.01, 3))[None, :]


@pytest.fixture(scope='module')
def board():
    factory = lambda: V4xPcFirmware(noisy, scaling=SCALING, init_delay=0.0).power_up()  # noqa: E731
    with VirtualBoard(factory) as vb:
        assert vb.wait_until(lambda b: b.firmware.running, TIMEOUT)
        yield vb


class Running:
    """A poller on its own thread, collecting what it hands on."""

    def __init__(self, path, poll_rate=1000.0, timeout=0.1):
        self.log = Log()
        self.poller = V4xPcPoller(
            V4xPcLink(path, timeout=timeout), Backoff(0.05, 0.2), self.log, poll_rate=poll_rate
        )
        self.poller.open()
        self.samples = []
        self.stop = threading.Event()
        self.thread = threading.Thread(
            target=self.poller.run, args=(self.stop, self._take), daemon=True
        )
        self.thread.start()

    def _take(self, stamps, values):
        self.samples.append((int(stamps[0]), values[0].copy()))

    def wait(self, predicate, what):
        deadline = time.monotonic() + TIMEOUT
        while not predicate():
            assert time.monotonic() < deadline, what
            time.sleep(0.005)

    def close(self):
        self.stop.set()
        self.thread.join(timeout=5.0)
        self.poller.close()


def resets(board):
    with board.lock:
        return board.firmware.requests[proto.RESET]


def test_samples_in_si_units_commands_as_pairs_and_resets(board):
    run = Running(board.path)
    try:
        run.poller.send(np.array([85, -85, -170, 170]))  # 1 A on x+, -2 A on y+
        run.wait(lambda: run.poller.applied.tolist() == [85, -85, -170, 170], 'the command')
        n = len(run.samples)
        run.wait(lambda: len(run.samples) > n + 50, 'samples')
        stamp, values = run.samples[-1]
        np.testing.assert_array_equal(
            values[3:], adc_current(np.array([1.0, -1.0, -2.0, 2.0])).astype(float)
        )
        with board.lock:
            assert board.firmware.pwm.tolist() == [85, -85, -170, 170]
            sent = [r for r in board.firmware.replies if r[0] == proto.READ_SENSORS][-3000:]
        fields = {proto.decode_reply(r, proto.READ_SENSORS).field_mT for r in sent}
        assert tuple(values[:3]) in {tuple(np.array(x) * 1e-3) for x in fields}  # mT -> T
        stamps = np.array([s for s, _ in run.samples])
        assert np.all(np.diff(stamps) > 0)
        assert abs(stamps[-1] - time.time_ns()) < 2e9
        # a command's latency is measured from the newest sample before it: the first
        # command has one only if the poller had read a sample before it was sent
        measured = len(run.poller.latencies_ns)
        assert measured <= 1
        run.poller.send(np.array([17, -17, 0, 0]))
        run.wait(lambda: len(run.poller.latencies_ns) == measured + 1, 'the latency of a command')
        # from the newest sample's stamp to the write: within a few poll periods
        assert 0 < run.poller.latencies_ns[-1] < 0.5e9
        before = resets(board)
        run.poller.send_zero()
        assert board.wait_until(lambda b: b.firmware.requests[proto.RESET] > before, TIMEOUT)
        with board.lock:
            assert board.firmware.pwm.tolist() == [0, 0, 0, 0]
        assert run.poller.counts['records'] == len(run.samples)
    finally:
        run.close()
    with board.lock:
        assert board.firmware.pwm.tolist() == [0, 0, 0, 0]


def test_garbage_from_the_board_resets_and_polling_goes_on(board):
    run = Running(board.path)
    try:
        run.poller.send(np.array([40, -40, 0, 0]))
        run.wait(lambda: run.poller.applied.tolist() == [40, -40, 0, 0], 'the command')
        before = resets(board)
        board.inject(b'\x05garbage\x00\x01')  # bytes no request asked for
        run.wait(lambda: run.poller.counts['io_errors'] >= 1, 'the link error')
        assert board.wait_until(lambda b: b.firmware.requests[proto.RESET] > before, TIMEOUT)
        n = len(run.samples)
        run.wait(lambda: len(run.samples) > n + 50, 'samples after the error')
        with board.lock:  # reset, and no old command re-applied without a new one
            assert board.firmware.pwm.tolist() == [0, 0, 0, 0]
        assert run.poller.state == 'connected'
    finally:
        run.close()


def test_poll_rate_is_kept(board):
    run = Running(board.path, poll_rate=500.0)
    try:
        run.wait(lambda: len(run.samples) > 600, 'samples')
        stamps = np.array([s for s, _ in run.samples[100:600]])
        rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) * 1e-9)
        assert rate <= 500.0 * 1.05  # paced, not free running (at least as slow)
    finally:
        run.close()


def test_the_boards_sensor_reset_is_no_link_error():
    """A field without noise reads alike 20 times: the board resets its sensor, 160 ms
    without replies. The driver's reply timeout outlasts it: no error, no coil reset."""
    factory = lambda: V4xPcFirmware(  # noqa: E731
        lambda pwm, t: np.array([[0.5, -0.3, 40.0]]), scaling=SCALING, init_delay=0.0
    ).power_up()
    with VirtualBoard(factory) as vb:
        assert vb.wait_until(lambda b: b.firmware.running, TIMEOUT)
        run = Running(vb.path, timeout=REPLY_TIMEOUT_S)
        try:
            run.poller.send(np.array([40, -40, 0, 0]))
            assert vb.wait_until(lambda b: b.firmware.freeze_resets >= 3, TIMEOUT)
            n = len(run.samples)
            run.wait(lambda: len(run.samples) > n + 20, 'samples after the resets')
            assert run.poller.counts['io_errors'] == 0
            with vb.lock:
                assert vb.firmware.pwm.tolist() == [40, -40, 0, 0]
        finally:
            run.close()


def test_bad_poll_rate():
    with pytest.raises(ValueError, match='poll_rate must be >= 0 Hz, got -1'):
        V4xPcPoller(V4xPcLink('/dev/null'), Backoff(0.1, 1.0), Log(), poll_rate=-1.0)
