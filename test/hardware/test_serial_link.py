import time
from functools import partial

import numpy as np
import pytest

from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.packet import encode_command
from maglev_ros.hardware.serial_link import Backoff, LinkError, SerialLink
from maglev_ros.hardware.v2x_stream import RecordDecoder
from maglev_ros.hardware.virtual_board import VirtualBoard


def test_backoff_grows_and_resets():
    backoff = Backoff(0.2, 1.0)
    assert [backoff.next_delay() for _ in range(5)] == pytest.approx([0.2, 0.4, 0.8, 1.0, 1.0])
    backoff.reset()
    assert backoff.next_delay() == 0.2
    with pytest.raises(ValueError, match='need 0 < initial <= maximum'):
        Backoff(2.0, 1.0)
    with pytest.raises(ValueError, match='factor must be >= 1, got 0.5'):
        Backoff(0.1, 1.0, factor=0.5)


def test_missing_device_is_a_link_error(tmp_path):
    link = SerialLink(str(tmp_path / 'nothing'), 9600)
    with pytest.raises(LinkError, match='cannot open'):
        link.open()
    with pytest.raises(LinkError, match='is not open'):
        link.read()
    with pytest.raises(ValueError, match='baudrate must be a positive int, got 0'):
        SerialLink('/dev/ttyACM0', 0)
    with pytest.raises(ValueError, match='port must be a non-empty path'):
        SerialLink('', 9600)


def test_read_write_and_unplug():
    factory = partial(V2xFirmware, LinearPlant.default(1), 1, startup_delay=0.05)
    with VirtualBoard(factory) as board:
        with SerialLink(board.path, 9600) as link:
            link.write(encode_command([1, 2, 3, 4]))
            decoder = RecordDecoder(1)
            deadline = time.monotonic() + 10.0
            while decoder.stats.records < 20:
                assert time.monotonic() < deadline
                decoder.feed(link.read())
            assert board.wait_until(lambda b: list(b.firmware.pwm) == [1, 2, 3, 4], 10.0)
            board.unplug()
            with pytest.raises(LinkError):
                for _ in range(100):
                    link.read()
            assert np.all(decoder.stats.dropped_bytes == 0)
        assert not link.is_open


def test_write_times_out_only_when_the_device_takes_no_data(monkeypatch):
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    try:
        with SerialLink(path, 115200, write_timeout=0.2) as link:
            # a complete write is no timeout, however late the thread runs afterwards
            clock = iter([0.0, 10.0, 20.0, 30.0])
            monkeypatch.setattr(time, 'monotonic', lambda: next(clock))
            link.write(b'\x01\x02\x03')
            monkeypatch.undo()
            assert os.read(master, 16) == b'\x01\x02\x03'
            # nobody reads the other end: the buffer fills, then the write times out
            start = time.monotonic()
            with pytest.raises(LinkError, match=f'{path} failed: the device took no data'):
                for _ in range(10_000):
                    link.write(bytes(1024))
            assert 0.15 < time.monotonic() - start < 30.0
    finally:
        os.close(master)
        os.close(slave)
