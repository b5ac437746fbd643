"""A firmware emulator behind the serial port's interface, on simulated time (ROS-free).

:class:`EmulatedPort` has the methods of
:class:`~maglev_ros.hardware.serial_link.SerialLink` that the links use
(``open``, ``close``, ``is_open``, ``read``, ``write``), but no pty and no
wall clock: the firmware emulator (e.g.
:class:`~maglev_ros.hardware.v4x_pc_firmware.V4xPcFirmware`) runs on the
port's own clock. Each :meth:`read` advances it by ``read_step`` (the time a
host's read waits for bytes) and returns what the board wrote meanwhile;
:meth:`sleep` advances it by a given time (a host waiting for its next
period). So a host loop on this port runs as fast as the machine computes,
with the board's timing exact and repeatable: what tests and lockstep
studies of a board loop use. The real-time check is the same loop against
``maglev-virtual-board`` on a pty.
"""

from __future__ import annotations

from .serial_link import LinkError

__all__ = ['EmulatedPort']


class EmulatedPort:
    """A firmware emulator as a serial port, on simulated time (module docstring).

    Parameters
    ----------
    firmware
        An emulator with ``receive(bytes)`` and ``advance_to(t_us) -> bytes``.
    read_step : float, optional
        s the board runs per :meth:`read` (the host's read wait), default 50 us.
    port : str, optional
        Name shown in messages.
    """

    def __init__(self, firmware, read_step: float = 50e-6, port: str = 'emulated board') -> None:
        if not read_step > 0:
            raise ValueError(f'read_step must be > 0 s, got {read_step!r}')
        self.firmware = firmware
        self.port = port
        self.read_step_us = max(1, round(read_step * 1e6))
        self.now_us = 0
        self.unplugged = False
        self._open = False
        self._pending = bytearray()

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._open

    def open(self) -> EmulatedPort:
        """Open the port (LinkError once unplugged)."""
        if self.unplugged:
            raise LinkError(f'cannot open {self.port}: unplugged')
        self._open = True
        return self

    def close(self) -> None:
        """Close the port (idempotent)."""
        self._open = False

    def unplug(self) -> None:
        """Pull the cable: reads and writes fail from now on (the firmware keeps its PWM)."""
        self.unplugged = True

    def plug(self) -> None:
        """Put the cable back (the same firmware: a board on its own supply)."""
        self.unplugged = False

    def clock(self) -> float:
        """Return the board's time since power-up, s."""
        return self.now_us * 1e-6

    def sleep(self, seconds: float) -> None:
        """Let the board run ``seconds`` (its output is kept for the next read).

        Parameters
        ----------
        seconds : float
            s (<= 0: nothing).
        """
        if seconds > 0:
            self._advance(self.now_us + max(1, round(seconds * 1e6)))

    def _advance(self, t_us: int) -> None:
        self._pending += self.firmware.advance_to(t_us)
        self.now_us = t_us

    def _check(self, what: str) -> None:
        if self.unplugged:
            raise LinkError(f'{what} {self.port} failed: device disconnected')
        if not self._open:
            raise LinkError(f'link to {self.port} is not open')

    def read(self) -> bytes:
        """Run the board one read step; return the bytes it wrote (possibly empty).

        Raises
        ------
        LinkError
            If the port is closed or unplugged.
        """
        self._check('read from')
        if not self._pending:
            self._advance(self.now_us + self.read_step_us)
        data, self._pending = bytes(self._pending), bytearray()
        return data

    def write(self, data: bytes) -> None:
        """Hand ``data`` to the board.

        Parameters
        ----------
        data : bytes
            Bytes to send.

        Raises
        ------
        LinkError
            If the port is closed or unplugged.
        """
        self._check('write to')
        self.firmware.receive(bytes(data))
