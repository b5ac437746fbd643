"""How many sensors a V2x board's records hold, found from its stream.

The V2x firmware does not announce its number of sensors N (a record is
``4 + 12 N + 8`` bytes with no marker, see :mod:`maglev_ros.hardware.v2x_stream`).
:func:`detect_sensor_count` decodes the same bytes for N = 1, 2, ... and
answers the smallest N whose decoder locks on consecutive, plausible
records. The smallest, because a stream of N-sensor records also decodes
as 2N, 3N, ... sensors (two records read as one: timestamps 2 sample periods
apart, the PWM and the next timestamp read as fields); a record size smaller
than the true one never locks (fields read as timestamps do not step by a
sample period). :func:`probe_sensor_count` reads a port until the answer is
clear or a time limit passes.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .serial_link import LinkError, SerialLink
from .v2x_stream import RecordDecoder

__all__ = ['MAX_SENSORS', 'SensorCountError', 'detect_sensor_count', 'probe_sensor_count']

MAX_SENSORS = 8  # sensors per record tried (the board's I2C multiplexer has 8 channels)
MIN_RECORDS = 20  # consecutive records that settle the count (4 ms of stream)
BOARD_PERIOD_US = 200  # us, the board's sample period
_TRY_BYTES = 16384  # the newest bytes a try decodes (over 100 records of 8 sensors)


class SensorCountError(RuntimeError):
    """The stream does not tell how many sensors its records hold."""


def detect_sensor_count(
    data: bytes, max_sensors: int = MAX_SENSORS, min_records: int = MIN_RECORDS
) -> int | None:
    """Return the sensors per record of a V2x stream, or None if it does not tell yet.

    Parameters
    ----------
    data : bytes
        The stream as read from the port (may start inside a record).
    max_sensors : int, optional
        Largest count tried.
    min_records : int, optional
        Records that must decode, with consecutive timestamps one sample
        period (200 us, within 50 %) apart, for a count to be taken.

    Returns
    -------
    int or None
        The smallest count whose records decode cleanly, or None when no
        count does (too few bytes, or not a V2x stream).
    """
    for n in range(1, max_sensors + 1):
        decoder = RecordDecoder(n)
        batch = decoder.feed(data)
        if len(batch) < min_records:
            continue
        steps = np.diff(batch.time_us)
        if abs(float(np.median(steps)) - BOARD_PERIOD_US) <= BOARD_PERIOD_US / 2:
            return n
    return None


def probe_sensor_count(
    port: str,
    timeout: float = 4.5,
    *,
    baudrate: int = 9600,
    open_link: Callable[[str, int], SerialLink] | None = None,
) -> int:
    """Open a V2x board's port, read its records and return their sensor count.

    The board starts its loop about 2 s after the port opens, so this takes
    2 to 3 s on a working board. The port is closed again before returning.

    Parameters
    ----------
    port : str
        Device path of the board (or of a ``maglev-virtual-board``).
    timeout : float, optional
        s: longest time to read before giving up.
    baudrate : int, optional
        Baud rate set on the port (USB CDC ignores it).
    open_link : callable, optional
        ``open_link(port, baudrate)`` returns an open :class:`SerialLink`
        (for tests); default opens ``SerialLink(port, baudrate)``.

    Returns
    -------
    int
        Sensors per record.

    Raises
    ------
    SensorCountError
        If the port cannot be opened, or no count is clear within ``timeout``
        (the message says what was received).
    """
    try:
        link = (open_link or _open)(port, baudrate)
    except LinkError as err:
        raise SensorCountError(str(err)) from None
    data = bytearray()
    now = time.monotonic()
    end, next_try = now + timeout, now
    try:
        while now < end:
            try:
                data += link.read()
            except LinkError as err:
                raise SensorCountError(f'{port}: {err}') from None
            now = time.monotonic()
            if data and now >= next_try:  # a try decodes up to 8 times: every 0.1 s
                next_try = now + 0.1
                n = detect_sensor_count(bytes(data[-_TRY_BYTES:]))
                if n is not None:
                    return n
    finally:
        link.close()
    what = 'nothing' if not data else f'{len(data)} bytes but no V2x sample records'
    raise SensorCountError(f'{port}: {what} in {timeout:g} s')


def _open(port: str, baudrate: int) -> SerialLink:
    return SerialLink(port, baudrate).open()
