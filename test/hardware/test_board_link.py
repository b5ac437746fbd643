"""The driver's board link, without ROS: back-off, samples handed on, packets, reconnect."""

import threading
import time
from functools import partial

import numpy as np

from maglev_ros.hardware.board_link import LINK_COUNTERS, BoardLink
from maglev_ros.hardware.board_stream import BoardStream
from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.serial_link import Backoff, SerialLink
from maglev_ros.hardware.virtual_board import VirtualBoard

TIMEOUT = 30.0  # s, generous: the machine is shared


class Log:
    """Collects (level, text) like a ROS logger."""

    def __init__(self):
        self.lines = []

    def info(self, text, **_):
        self.lines.append(('info', text))

    def warning(self, text, **_):
        self.lines.append(('warning', text))

    def error(self, text, **_):
        self.lines.append(('error', text))


def wait(predicate, what):
    deadline = time.monotonic() + TIMEOUT
    while not predicate():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.005)


class Running:
    """A BoardLink's loop in a thread, stopped on exit."""

    def __init__(self, path, writes=True, min_delay=0.05):
        scaling = CurrentScaling(1000.0)
        self.stream = BoardStream('v2x', 1, scaling)
        self.log = Log()
        self.link = BoardLink(
            SerialLink(path, 9600), self.stream, Backoff(min_delay, 0.2), self.log, writes
        )
        self.samples = []
        self.zeros = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(
            target=self.link.run, args=(self.stop, self._publish, self._zero), daemon=True
        )

    def _publish(self, stamps, values):
        self.samples.append((stamps.copy(), values.copy()))

    def _zero(self):
        self.zeros += 1
        self.link.send(np.zeros(4, dtype=np.int64))

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(timeout=TIMEOUT)
        self.link.close()


def test_a_missing_port_waits_with_back_off(tmp_path):
    with Running(str(tmp_path / 'no-board')) as r:
        wait(lambda: r.link.state == 'waiting for board', 'the first attempt')
        wait(lambda: len(r.log.lines) >= 1, 'the warning')
    level, text = r.log.lines[0]
    assert level == 'warning' and 'cannot open' in text and 'retrying in' in text
    assert r.zeros == 0 and r.link.counts == dict.fromkeys(LINK_COUNTERS, 0)


def test_samples_packets_and_reconnect():
    board = VirtualBoard(partial(V2xFirmware, LinearPlant.default(1), 1, startup_delay=0.05))
    with board, Running(board.path) as r:
        wait(lambda: r.link.counts['records'] > 100, 'records')
        assert r.link.state == 'connected' and r.zeros == 1  # zero currents on connecting
        assert ('info', f'connected to {board.path}') in r.log.lines
        samples = list(r.samples)  # the loop appends; counted after handing on
        stamps = np.concatenate([s for s, _ in samples])
        assert stamps.size >= 100 and np.all(np.diff(stamps) > 0)
        assert samples[0][1].shape[1] == 3 + 4  # one sensor's field, 4 currents
        r.link.send(np.array([5, -5, 7, -7], dtype=np.int64))  # the only writer now
        assert board.wait_until(lambda b: list(b.firmware.pwm) == [5, -5, 7, -7], TIMEOUT)
        assert r.link.applied.tolist() == [5, -5, 7, -7]
        assert r.link.counts['commands_sent'] == 2
        board.unplug()
        wait(lambda: r.link.state != 'connected', 'link loss')
        board.plug()
        wait(lambda: r.link.counts['reconnects'] == 1, 'reconnect')
        wait(lambda: r.zeros == 2, 'zero after reconnecting')
    assert any(level == 'warning' and 'link lost' in text for level, text in r.log.lines)


def idle_link(tmp_path, firmware):
    """A link on a port that does not exist (never opened)."""
    stream = BoardStream(firmware, 1, CurrentScaling(1000.0))
    path = str(tmp_path / 'x')
    return BoardLink(SerialLink(path, 9600), stream, Backoff(0.1, 0.2), Log(), firmware == 'v2x')


def test_a_read_only_board_gets_no_packets(tmp_path):
    link = idle_link(tmp_path, 'v4x')
    link.send(np.ones(4, dtype=np.int64))  # not open, but nothing is attempted
    assert link.counts['commands_unsent'] == 0 and link.counts['commands_sent'] == 0


def test_an_unsent_packet_is_counted(tmp_path):
    link = idle_link(tmp_path, 'v2x')
    link.send(np.ones(4, dtype=np.int64))  # the port is not open
    assert link.counts['commands_unsent'] == 1 and link.applied.tolist() == [0, 0, 0, 0]
