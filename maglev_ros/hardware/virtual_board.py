"""A virtual Maggy board behind a pseudo-terminal (Linux).

``VirtualBoard`` runs a firmware emulator (``firmware.V2xFirmware``,
``V4xFirmware`` or ``v4x_pc_firmware.V4xPcFirmware``) paced to the wall
clock in a background thread and connects it to the master side of a pty.
Hosts open the slave side through a stable symlink (``path``), exactly like
a USB serial device, e.g. with ``serial.Serial(board.path)``.

* Port open and close by the host are detected on the master side (a read
  fails with EIO while no process holds the slave open); each open makes the
  firmware wait its start-up delay, as the real board does. While no host
  is connected the loop keeps running (watchdog included) and its output is
  discarded.
* ``unplug`` closes the pty (the host's reads fail) and removes the
  symlink; ``plug`` powers up a fresh firmware on a new pty and re-points the
  symlink, so a host can reconnect with the same path.
* Output the host does not read fast enough waits in a backlog of up to
  1 MiB (about 8 s of 1-sensor data: a busy host does not lose data, as with
  USB flow control); beyond that, new output is dropped (counted), like a
  board whose USB writes time out.
"""

from __future__ import annotations

import errno
import os
import select
import shutil
import tempfile
import threading
import time
import tty
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..realtime_priority import fifo_priority
from .firmware import V2xFirmware, V4xFirmware
from .v4x_pc_firmware import V4xPcFirmware

__all__ = ['BoardStatus', 'VirtualBoard', 'VirtualBoardError']

Firmware = V2xFirmware | V4xFirmware | V4xPcFirmware
_POLL_S = 0.0005  # s: input poll and pacing granularity (bursts are 1 ms apart)
_CLOSED_POLL_S = 0.002  # s: how often a closed port is checked for a new open
_MAX_BACKLOG = 1 << 20  # bytes held for a slow host (about 8 s of 1-sensor V2x data)


class VirtualBoardError(ValueError):
    """Invalid virtual-board argument or use of a closed board."""


@dataclass(frozen=True)
class BoardStatus:
    """Counters of a ``VirtualBoard``.

    Attributes
    ----------
    plugged : bool
        Whether the board is plugged in (a pty exists).
    port_open : bool
        Whether a host holds the port open.
    port_opens : int
        Host opens seen since the board was created.
    plugs : int
        Times the board was plugged in (1 after ``open``).
    bytes_written, bytes_received, bytes_dropped : int
        Bytes written to and read from the host, and output dropped because
        the host did not read it (backlog full).
    """

    plugged: bool
    port_open: bool
    port_opens: int
    plugs: int
    bytes_written: int
    bytes_received: int
    bytes_dropped: int


class VirtualBoard:
    """A firmware emulator on a pty, paced to the wall clock.

    Parameters
    ----------
    firmware_factory : callable
        Called with no arguments at every power-up (``open`` and ``plug``);
        returns a fresh ``V2xFirmware``, ``V4xFirmware`` or ``V4xPcFirmware``.
        The board's clock goes on from the firmware's own (``now_us``): a
        firmware that has already run (``V4xPcFirmware.power_up``, or the same
        one again at a plug: a board on its own supply) is not restarted.
    link : str or Path, optional
        Stable device path (a symlink to the current pty). Default: a new
        temporary directory holding ``ttyMAGGY0``, removed on ``close``.
    realtime_priority : int, optional
        ``SCHED_FIFO`` priority of the pacing thread, 1-99
        (:func:`~maglev_ros.realtime_priority.fifo_priority`); 0 (default): the
        normal policy. :attr:`priority_note` says why it was not applied.
    """

    def __init__(
        self,
        firmware_factory: Callable[[], Firmware],
        *,
        link: str | os.PathLike | None = None,
        realtime_priority: int = 0,
    ) -> None:
        if not callable(firmware_factory):
            raise VirtualBoardError(
                f'firmware_factory must be callable, got {type(firmware_factory).__name__}'
            )
        self._factory = firmware_factory
        if not 0 <= realtime_priority <= 99:
            raise VirtualBoardError(
                f'realtime_priority must be 0 (none) to 99, got {realtime_priority!r}'
            )
        self._priority = int(realtime_priority)
        self.priority_note = ''
        self._link_arg = Path(link) if link is not None else None
        if self._link_arg is not None and not self._link_arg.parent.is_dir():
            raise VirtualBoardError(f'link directory does not exist: {self._link_arg.parent}')
        if self._link_arg is not None and (
            self._link_arg.exists() and not self._link_arg.is_symlink()
        ):
            raise VirtualBoardError(f'link exists and is not a symlink: {self._link_arg}')
        self._tmpdir: str | None = None
        self._link: Path | None = None
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._paused = threading.Event()
        self._tampers: deque[Callable[[bytes], bytes]] = deque()
        self._backlog = bytearray()  # output the host has not taken yet
        self._master: int | None = None
        self._device: str | None = None
        self._firmware: Firmware | None = None
        self._poll_s = _POLL_S
        self._on_arrival = False
        self._t0 = 0.0
        self._port_open = False
        self._port_opens = 0
        self._plugs = 0
        self._written = 0
        self._received = 0
        self._dropped = 0
        self._error: BaseException | None = None

    # -- handle -------------------------------------------------------------------

    def open(self) -> VirtualBoard:
        """Create the pty and the symlink, power up, start the pacing thread.

        Returns
        -------
        VirtualBoard
            ``self``.
        """
        if self._thread is not None:
            raise VirtualBoardError('virtual board is already open')
        if self._link_arg is None:
            self._tmpdir = tempfile.mkdtemp(prefix='maglev-board-')
            self._link = Path(self._tmpdir) / 'ttyMAGGY0'
        else:
            self._link = self._link_arg
        self._stop.clear()
        self.plug()
        self._thread = threading.Thread(target=self._run, name='maglev-virtual-board', daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread, close the pty and remove the symlink (idempotent)."""
        thread, self._thread = self._thread, None
        self._stop.set()
        if thread is not None:
            thread.join(timeout=5.0)
        self.unplug()
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None

    def __enter__(self) -> VirtualBoard:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- public state -------------------------------------------------------------

    @property
    def path(self) -> str:
        """Stable device path (symlink) for hosts to open."""
        if self._link is None:
            raise VirtualBoardError('virtual board is not open')
        return str(self._link)

    @property
    def device(self) -> str | None:
        """Current pty slave device (changes on every plug), or None if unplugged."""
        return self._device

    @property
    def lock(self) -> threading.RLock:
        """Lock held while the thread advances the firmware (hold it to inspect)."""
        return self._lock

    @property
    def firmware(self) -> Firmware:
        """The current firmware emulator (inspect it while holding ``lock``)."""
        if self._firmware is None:
            raise VirtualBoardError('virtual board is unplugged')
        return self._firmware

    @property
    def status(self) -> BoardStatus:
        """Snapshot of the counters."""
        with self._lock:
            return BoardStatus(
                self._master is not None,
                self._port_open,
                self._port_opens,
                self._plugs,
                self._written,
                self._received,
                self._dropped,
            )

    def check(self) -> None:
        """Re-raise an exception that stopped the pacing thread, if any."""
        if self._error is not None:
            raise RuntimeError('virtual board thread failed') from self._error

    # -- faults and plugging ----------------------------------------------------

    def tamper_next_burst(self, edit: Callable[[bytes], bytes]) -> None:
        """Pass the next output the host receives through ``edit`` (fault injection).

        The edit applies to the next write to an open port: one burst (V2x)
        or line (V4x), or several if the loop had to catch up.

        Parameters
        ----------
        edit : callable
            ``edit(bytes) -> bytes`` applied to the next output.
        """
        with self._lock:
            self._tampers.append(edit)

    def inject(self, data: bytes) -> None:
        """Write raw bytes to the host now, between two bursts.

        Parameters
        ----------
        data : bytes
            Raw bytes for the host.
        """
        with self._lock:
            if self._master is not None and self._port_open:
                self._write(data)

    def unplug(self) -> None:
        """Simulate pulling the USB cable: close the pty, remove the symlink."""
        with self._lock:
            if self._master is not None:
                os.close(self._master)
            self._master = None
            self._device = None
            self._firmware = None
            self._port_open = False
            self._backlog.clear()
            if self._link is not None and self._link.is_symlink():
                self._link.unlink()

    def plug(self) -> None:
        """Simulate plugging in: power up a new firmware on a new pty."""
        with self._lock:
            if self._link is None:
                raise VirtualBoardError('virtual board is not open')
            self.unplug()
            master, slave = os.openpty()
            tty.setraw(slave)  # no echo, no line discipline: bytes pass unchanged
            device = os.ttyname(slave)
            os.close(slave)  # a host open is then visible on the master side
            os.set_blocking(master, False)
            tmp = self._link.with_name(self._link.name + '.new')
            if tmp.is_symlink() or tmp.exists():
                tmp.unlink()
            os.symlink(device, tmp)
            os.replace(tmp, self._link)
            self._firmware = self._factory()
            # a firmware that samples faster than the default poll is paced at its
            # own rate (V4x PC control: 200 us), so a request finds it caught up
            self._poll_s = min(_POLL_S, getattr(self._firmware, 'pacing_period', _POLL_S))
            self._on_arrival = bool(getattr(self._firmware, 'answers_on_arrival', False))
            self._master = master
            self._device = device
            # the board's clock goes on from the firmware's own: a factory may return a
            # board that has run (powered before the port opens, or through an unplug)
            self._t0 = time.monotonic() - getattr(self._firmware, 'now_us', 0) * 1e-6
            self._plugs += 1

    def pause(self) -> None:
        """Stall the board's loop (no new output, no parsing) until ``resume``.

        The clock keeps running: on ``resume`` the loop catches up and writes
        the samples of the stall at once, like a board whose USB link stalled.
        Bytes written before the stall that the pty had not taken yet still
        reach the host.
        """
        self._paused.set()

    def resume(self) -> None:
        """End a ``pause``."""
        self._paused.clear()

    def replug(self, downtime: float = 0.0) -> None:
        """Unplug, wait ``downtime`` seconds, plug in again.

        Parameters
        ----------
        downtime : float
            Seconds unplugged.
        """
        self.unplug()
        if downtime > 0:
            time.sleep(downtime)
        self.plug()

    def wait_until(self, predicate: Callable[[VirtualBoard], bool], timeout: float) -> bool:
        """Poll ``predicate(self)`` (with ``lock`` held) until true or timeout.

        Parameters
        ----------
        predicate : callable
            ``predicate(board) -> bool``.
        timeout : float
            Seconds to wait at most.

        Returns
        -------
        bool
            Whether the predicate became true.
        """
        deadline = time.monotonic() + timeout
        while True:
            with self._lock:
                if predicate(self):
                    return True
            if time.monotonic() > deadline:
                return False
            self.check()
            time.sleep(0.005)

    # -- thread -------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        """Queue output for the host; beyond the backlog limit, drop it (counted)."""
        if len(self._backlog) + len(data) > _MAX_BACKLOG:
            self._dropped += len(data)
            return
        self._backlog += data
        self._flush()

    def _flush(self) -> None:
        """Write as much of the backlog as the pty takes now."""
        if not self._backlog or self._master is None:
            return
        try:
            n = os.write(self._master, self._backlog)
        except BlockingIOError:
            return
        except OSError as err:
            if err.errno != errno.EIO:
                raise
            self._port_closed()
            return
        self._written += n
        del self._backlog[:n]

    def _port_closed(self) -> None:
        self._port_open = False  # no process holds the slave open
        self._backlog.clear()  # what a closed port was sent is lost

    def _poll_input(self) -> bool:
        """Read host bytes; track port open/close through EIO; return whether bytes came."""
        try:
            data = os.read(self._master, 4096)
        except BlockingIOError:
            data = b''
        except OSError as err:
            if err.errno != errno.EIO:
                raise
            self._port_closed()
            return False
        if not self._port_open:
            self._port_open = True
            self._port_opens += 1
            self._firmware.port_opened()
        if data:
            self._received += len(data)
            self._firmware.receive(data)
        return bool(data)

    def _run(self) -> None:
        with fifo_priority(self._priority) as note:
            self.priority_note = note
            self._pace()

    def _pace(self) -> None:
        try:
            while not self._stop.is_set():
                with self._lock:
                    master = self._master
                    if master is not None and not self._paused.is_set():
                        # a request/response firmware (V4x PC control): the board's samples
                        # up to now first, with the commands it had: the thread wakes when
                        # the host's bytes come (select), so they arrived now, and the
                        # firmware answers them now, from its latest sample; taken before
                        # the catch-up, a request would be answered (and a command applied)
                        # up to a wait earlier than it was sent. A streaming firmware (V2x)
                        # takes them first: a command drives the samples computed now.
                        now_us = int((time.monotonic() - self._t0) * 1e6)
                        if self._on_arrival:
                            out = self._firmware.advance_to(now_us)
                            was_open = self._port_open
                            got = self._poll_input()
                            if not was_open:
                                out = b''  # written before the host opened the port: lost
                            if got:
                                out += self._firmware.advance_to(now_us)
                        else:  # a streaming firmware: the bytes drive the samples of now
                            self._poll_input()
                            out = self._firmware.advance_to(now_us)
                        if out and self._port_open:
                            if self._tampers:
                                out = self._tampers.popleft()(out)
                            self._write(out)
                        else:
                            self._flush()
                    port_open = self._port_open
                    waiting = [master] if self._backlog else []
                if master is None or not port_open or self._paused.is_set():
                    if port_open and self._backlog:  # bytes sent before a stall still arrive
                        with self._lock:
                            self._flush()
                    time.sleep(_CLOSED_POLL_S)
                    continue
                try:
                    select.select([master], waiting, [], self._poll_s)
                except (OSError, ValueError):  # closed by unplug meanwhile
                    continue
        except BaseException as err:  # surfaced by check()
            self._error = err
