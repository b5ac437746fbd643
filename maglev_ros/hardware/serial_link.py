"""Serial port handle for the board, and the reconnect back-off.

``SerialLink`` wraps ``serial.Serial`` with open/close, a context manager
and one error type (``LinkError``, an ``OSError``) for everything that
means "the board is gone": a missing device, a read or write failing after
an unplug, a write that blocks. ``Backoff`` spaces reconnection attempts.
"""

from __future__ import annotations

import os
import select
import threading
import time

import serial

__all__ = ['Backoff', 'LinkError', 'SerialLink']

_READ_SIZE = 65536  # bytes per read at most (about 0.5 s of V2x data with 3 sensors)


class LinkError(OSError):
    """The serial link failed (device missing, unplugged or stuck)."""


class Backoff:
    """Exponential back-off between reconnection attempts.

    Parameters
    ----------
    initial : float
        First delay in s (> 0).
    maximum : float
        Largest delay in s (>= initial).
    factor : float, optional
        Growth per failed attempt (>= 1).
    """

    def __init__(self, initial: float, maximum: float, factor: float = 2.0) -> None:
        if not 0 < initial <= maximum:
            raise ValueError(
                f'need 0 < initial <= maximum, got initial={initial!r}, maximum={maximum!r}'
            )
        if not factor >= 1:
            raise ValueError(f'factor must be >= 1, got {factor!r}')
        self.initial = float(initial)
        self.maximum = float(maximum)
        self.factor = float(factor)
        self._next = self.initial

    def next_delay(self) -> float:
        """Return the delay before the next attempt (s) and grow it."""
        delay = self._next
        self._next = min(self._next * self.factor, self.maximum)
        return delay

    def reset(self) -> None:
        """Start again from the initial delay (after a success)."""
        self._next = self.initial


class SerialLink:
    """The host side of the board's serial port.

    Parameters
    ----------
    port : str
        Device path (e.g. ``/dev/ttyACM0`` or a virtual board's symlink).
    baudrate : int
        Baud rate (ignored by USB CDC, but set: 9600 for V2x, 115200 for V4x).
    read_timeout : float, optional
        Longest a ``read`` blocks waiting for the first byte, in s.
    write_timeout : float, optional
        Longest a ``write`` may block, in s; longer means the board is stuck.
    """

    def __init__(
        self,
        port: str,
        baudrate: int,
        *,
        read_timeout: float = 0.05,
        write_timeout: float = 0.1,
    ) -> None:
        if not isinstance(port, str) or not port:
            raise ValueError(f'port must be a non-empty path, got {port!r}')
        if not isinstance(baudrate, int) or baudrate <= 0:
            raise ValueError(f'baudrate must be a positive int, got {baudrate!r}')
        self.port = port
        self.baudrate = baudrate
        self.read_timeout = read_timeout
        self.write_timeout = write_timeout
        self._serial: serial.Serial | None = None
        self._write_lock = threading.Lock()
        self._poll: select.poll | None = None
        self._poll_fd = -1
        self._timeout_ms = max(0, round(read_timeout * 1000))

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._serial is not None

    def open(self) -> SerialLink:
        """Open the port.

        Returns
        -------
        SerialLink
            ``self``.

        Raises
        ------
        LinkError
            If the device cannot be opened.
        """
        if self._serial is not None:
            return self
        try:
            self._serial = serial.Serial(
                self.port,
                self.baudrate,
                timeout=self.read_timeout,
                write_timeout=self.write_timeout,
            )
        except (serial.SerialException, OSError) as err:
            raise LinkError(f'cannot open {self.port}: {err}') from err
        return self

    def close(self) -> None:
        """Close the port (idempotent; errors while closing are ignored)."""
        ser, self._serial = self._serial, None
        self._poll, self._poll_fd = None, -1
        if ser is not None:
            try:
                ser.close()
            except (serial.SerialException, OSError):
                pass

    def __enter__(self) -> SerialLink:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _port(self) -> serial.Serial:
        ser = self._serial
        if ser is None:
            raise LinkError(f'link to {self.port} is not open')
        return ser

    def read(self) -> bytes:
        """Read what is available, waiting up to ``read_timeout`` for the first byte.

        Returns
        -------
        bytes
            Possibly empty.

        Raises
        ------
        LinkError
            If the device failed (e.g. was unplugged).
        """
        ser = self._port()
        # poll + one os.read returns everything available in one call;
        # pyserial's read(in_waiting or 1) often returns a single byte first,
        # doubling the calls per burst. (POSIX: pyserial exposes the fd.)
        try:
            fd = ser.fileno()
            if self._poll_fd != fd:
                self._poll = select.poll()
                self._poll.register(fd, select.POLLIN)
                self._poll_fd = fd
            if not self._poll.poll(self._timeout_ms):
                return b''
            data = os.read(fd, _READ_SIZE)
        except (serial.SerialException, OSError, TypeError, ValueError) as err:
            raise LinkError(f'read from {self.port} failed: {err}') from err
        if not data:  # readable but empty: the device went away
            raise LinkError(f'read from {self.port} failed: device disconnected')
        return data

    def write(self, data: bytes) -> None:
        """Write all of ``data``.

        Parameters
        ----------
        data : bytes
            Bytes to send.

        Raises
        ------
        LinkError
            If the device failed or the write blocked longer than ``write_timeout``.
        """
        with self._write_lock:
            ser = self._port()
            # os.write on the (non-blocking) fd, waiting for room only while the device's
            # buffer is full: pyserial's write raises 'Write timeout' after a complete
            # write when the thread was descheduled for write_timeout (a loaded machine)
            try:
                fd = ser.fileno()
                view = memoryview(bytes(data))
                deadline = time.monotonic() + self.write_timeout
                while view:
                    try:
                        view = view[os.write(fd, view) :]
                    except BlockingIOError:
                        pass
                    if not view:
                        break
                    left = deadline - time.monotonic()
                    if left <= 0 or not select.select([], [fd], [], left)[1]:
                        raise LinkError(
                            f'write to {self.port} failed: the device took no data for '
                            f'{self.write_timeout:g} s'
                        )
            except LinkError:
                raise
            except (serial.SerialException, OSError, TypeError, ValueError) as err:
                raise LinkError(f'write to {self.port} failed: {err}') from err
