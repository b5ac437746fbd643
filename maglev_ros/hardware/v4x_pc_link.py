"""Request/response link to a board running the V4x PC-control firmware (ROS-free).

``V4xPcLink`` opens the port, checks the board with the ping (``AA`` ->
``EE``), and then makes one request at a time: read the sensors, read the
currents, command the two pair differences, reset the coils (``04``), read
the status. Every request waits for its reply up to ``timeout``.

**No watchdog on the board.** The firmware keeps the last PWM until told
otherwise, so the link resets the coils (``04``) on ``close`` (also when the
``with`` block ends by an exception), after a reply timeout and after a link
error (best effort: the port may be gone).

**Resynchronisation.** After a timeout or a reply that is not the answer to
the request (garbage, a late reply, a half frame), the link sends a lone
``0x00`` (it ends a half frame the board may be waiting on, which would
otherwise stall its loop for 1 s per missing byte; a lone ``0x00`` gets no
reply), waits until the port is quiet, drops what came meanwhile, and pings
until ``EE`` comes back. It then raises the error; the caller decides whether
to go on (the next request works again).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import v4x_pc_protocol as proto
from .cobs_frame import DELIMITER, FrameError, decode_frame
from .serial_link import LinkError, SerialLink

__all__ = [
    'FIRMWARE_NAME',
    'Cycle',
    'V4X_PC_BAUD',
    'BoardReplyError',
    'LinkCounts',
    'ReplyTimeoutError',
    'V4xPcLink',
]

FIRMWARE_NAME = 'V4x PC-control firmware (V4x_python-interface_last-version)'
V4X_PC_BAUD = 115200  # ignored by USB CDC, set anyway
_QUIET_S = 0.02  # s without bytes that ends the drain of a resynchronisation
_POLL_S = 0.002  # s: longest single wait for bytes inside a request
_TIMEOUT = 'timeout'
_MAX_REPLY = 27  # bytes of the longest reply frame (01: 25 bytes, COBS + 1, delimiter)


class ReplyTimeoutError(LinkError):
    """The board did not answer a request in time."""


class BoardReplyError(LinkError):
    """The board answered with its error reply (``00 67``: unknown request)."""


@dataclass(frozen=True)
class Cycle:
    """What one :meth:`V4xPcLink.cycle` returns.

    Attributes
    ----------
    stamp_ns : int
        Host time (``time.time_ns``) when the sensor reply had arrived, ns.
    field_mT : ndarray, shape (3,)
        Processed Bx, By, Bz, mT (see docs/boards.md: baseline and feedthrough
        removed, x and y low-pass filtered).
    rate_mT_s : ndarray, shape (3,)
        dBx, dBy, dBz, mT/s (dBz is always 0).
    currents_A : ndarray, shape (4,)
        Coil currents, A, order x+, x-, y+, y-.
    """

    stamp_ns: int
    field_mT: np.ndarray  # noqa: N815 (unit symbol mT)
    rate_mT_s: np.ndarray  # noqa: N815 (unit symbol mT)
    currents_A: np.ndarray  # noqa: N815 (unit symbol A)


@dataclass
class LinkCounts:
    """Counters of a ``V4xPcLink``.

    Attributes
    ----------
    requests : int
        Requests answered correctly.
    timeouts : int
        Requests not answered in time.
    bad_replies : int
        Replies that were not the answer to their request (and error replies).
    resyncs : int
        Resynchronisations made.
    dropped_bytes : int
        Bytes read and thrown away (garbage, late replies, invalid frames).
    resets : int
        ``04`` requests answered.
    """

    requests: int = 0
    timeouts: int = 0
    bad_replies: int = 0
    resyncs: int = 0
    dropped_bytes: int = 0
    resets: int = 0


class V4xPcLink:
    """A board running the V4x PC-control firmware, behind a serial port.

    Parameters
    ----------
    port : str
        Device path (``/dev/ttyACM0``, a virtual board's symlink).
    timeout : float, optional
        s to wait for each reply (the board answers within a sample, about
        0.2 ms, except during its 160 ms sensor reset).
    open_timeout : float, optional
        s to wait for the first ping's answer: the board's set-up takes about
        4.3 s after power-up, and it answers once set-up ends.
    serial_link : SerialLink, optional
        The port handle (default: a ``SerialLink`` at 115200 baud).
    clock : callable, optional
        Monotonic time, s, of the timeouts (default :func:`time.monotonic`; an
        :class:`~maglev_ros.hardware.emulated_port.EmulatedPort`'s clock runs
        them on the emulated board's time).

    Examples
    --------
    >>> with V4xPcLink('/dev/ttyACM0') as board:  # doctest: +SKIP
    ...     board.command(40, -20)
    ...     field_mT, rate = board.read_sensors()
    """

    def __init__(
        self,
        port: str,
        *,
        timeout: float = 0.1,
        open_timeout: float = 6.0,
        serial_link: SerialLink | None = None,
        clock=time.monotonic,
    ) -> None:
        if not timeout > 0 or not open_timeout > 0:
            raise ValueError(
                f'timeout and open_timeout must be > 0 s, got {timeout!r}, {open_timeout!r}'
            )
        self.port = port
        self._clock = clock
        self.timeout = float(timeout)
        self.open_timeout = float(open_timeout)
        self._serial = serial_link or SerialLink(port, V4X_PC_BAUD, read_timeout=_POLL_S)
        self.counts = LinkCounts()
        self.last_command: tuple[int, int] | None = None  # (p_x, p_y) last acknowledged
        self._open = False

    # -- handle ---------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        """Whether the port is open and the board answered the ping."""
        return self._open

    def open(self) -> V4xPcLink:
        """Open the port, check the board with the ping, and reset its coils (``04``).

        The board has no watchdog: it may still drive the PWM of an earlier
        session (or of garbage it took for a ``03``), so the link starts from zero.

        Returns
        -------
        V4xPcLink
            ``self``.

        Raises
        ------
        LinkError
            If the port cannot be opened, or nothing answers the ping within
            ``open_timeout`` (the message names the port and the firmware).
        """
        self._serial.open()
        try:
            self._resync(self.open_timeout)
            try:
                self.reset()
            except LinkError:
                # a ping's answer that came after its wait (a board or host running
                # late) precedes the reply: the link resynchronised meanwhile, try again
                self.reset()
        except LinkError:
            self._serial.close()
            raise
        self._open = True
        return self

    def close(self) -> None:
        """Reset the coils (``04``, best effort), then close the port (idempotent)."""
        if self._open:
            self._safe_reset()
        self._open = False
        self._serial.close()

    def __enter__(self) -> V4xPcLink:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- requests -------------------------------------------------------------------------

    def ping(self, timeout: float | None = None) -> bool:
        """Send ``AA``; return whether exactly the byte ``EE`` came back in time.

        Parameters
        ----------
        timeout : float, optional
            s to wait (default: the link's ``timeout``).

        Returns
        -------
        bool
            True when ``EE`` came back.
        """
        self._serial.write(proto.request(proto.PING))
        deadline = self._clock() + (self.timeout if timeout is None else timeout)
        while self._clock() < deadline:
            data = self._serial.read()
            if data == bytes([proto.PING_REPLY]):
                return True
            self.counts.dropped_bytes += len(data)
        return False

    def read_sensors(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Request ``01``: the processed field (mT) and its derivative (mT/s), each (3,)."""
        reply = self._transact(proto.request(proto.READ_SENSORS), proto.READ_SENSORS)
        return np.array(reply.field_mT), np.array(reply.rate_mT_s)

    def read_currents(self) -> NDArray[np.float64]:
        """Request ``02``: coil currents in A, shape (4,), order x+, x-, y+, y-."""
        reply = self._transact(proto.request(proto.READ_CURRENTS), proto.READ_CURRENTS)
        return np.array(reply.currents_A)

    def command(self, p_x: int, p_y: int) -> None:
        """Request ``03``: PWM ``p_x`` on x+ (``-p_x`` on x-), ``p_y`` on y+ (``-p_y`` on y-).

        Parameters
        ----------
        p_x, p_y : int
            Pair differences, -255 .. 255.
        """
        self._transact(proto.set_pwm_request(p_x, p_y), proto.SET_PWM)
        self.last_command = (int(p_x), int(p_y))

    def reset(self) -> None:
        """Request ``04``: all coils to PWM 0."""
        self._transact(proto.request(proto.RESET), proto.RESET)
        self.last_command = (0, 0)
        self.counts.resets += 1

    def status(self) -> proto.StatusReply:
        """Request ``05``: the status bytes and the board's uptime."""
        return self._transact(proto.request(proto.STATUS), proto.STATUS)

    def command_and_sample(self, p_x: int, p_y: int) -> Cycle:
        """Apply a command, then read the sensors and the currents: one round trip.

        ``03``, ``01`` and ``02`` go in one write; the board answers them in
        order within one loop pass, so the field is its latest sample taken
        before the command (the command drives the coils from its next
        sample on) and the currents its ADC reading with the command applied.
        (:meth:`cycle` sends them the other way round: the currents before
        the command.)

        Parameters
        ----------
        p_x, p_y : int
            Pair differences to apply, -255 .. 255.

        Returns
        -------
        Cycle
            Host time at the first reply, field, rate and currents.
        """
        return self._round_trip(p_x, p_y, command_first=True)

    def cycle(self, p_x: int, p_y: int) -> Cycle:
        """One control step in one round trip: ``01``, ``02`` and ``03`` sent together.

        The board answers the three in order (it reads one frame per loop pass,
        microseconds apart), so a step costs one round trip instead of three.
        The field is the board's latest sample before the command, the currents
        its ADC reading just before the command is applied.

        Parameters
        ----------
        p_x, p_y : int
            Pair differences to apply, -255 .. 255.

        Returns
        -------
        Cycle
            Host time at the sensor reply, field, rate and currents.
        """
        return self._round_trip(p_x, p_y, command_first=False)

    # -- internals ------------------------------------------------------------------------

    def _round_trip(self, p_x: int, p_y: int, command_first: bool) -> Cycle:
        """Send ``03`` with ``01`` and ``02`` in one write (``03`` first or last); one Cycle."""
        reads = proto.request(proto.READ_SENSORS) + proto.request(proto.READ_CURRENTS)
        command = proto.set_pwm_request(p_x, p_y)
        codes = (proto.READ_SENSORS, proto.READ_CURRENTS)
        if command_first:
            (_, sensors, currents), stamp_ns = self._exchange(
                command + reads, (proto.SET_PWM, *codes)
            )
        else:
            (sensors, currents, _), stamp_ns = self._exchange(
                reads + command, (*codes, proto.SET_PWM)
            )
        self.last_command = (int(p_x), int(p_y))
        return Cycle(
            stamp_ns,
            np.array(sensors.field_mT),
            np.array(sensors.rate_mT_s),
            np.array(currents.currents_A),
        )

    def _transact(self, frame: bytes, code: int):
        return self._exchange(frame, (code,))[0][0]

    def _exchange(self, frames: bytes, codes: tuple[int, ...]) -> tuple[list, int]:
        """Send request frames; return their replies and the host time (ns) of the first."""
        names = ' '.join(f'{c:02x}' for c in codes)
        try:
            self._serial.write(frames)
            payloads, problem, stamp_ns = self._read_frames(
                self._clock() + self.timeout, len(codes)
            )
        except LinkError:
            self._safe_reset()  # the port may be gone: best effort
            raise
        if problem == _TIMEOUT:
            self.counts.timeouts += 1
            self._recover()
            raise ReplyTimeoutError(
                f'{self.port}: no reply to request {names} within {self.timeout:g} s '
                f'(the {FIRMWARE_NAME} answers every request); coils reset'
            )
        try:
            if problem:
                raise proto.ProtocolError(problem)
            replies = [proto.decode_reply(p, c) for p, c in zip(payloads, codes, strict=True)]
        except proto.ProtocolError as err:
            self.counts.bad_replies += 1
            self.counts.dropped_bytes += sum(len(p) for p in payloads)
            self._recover()
            raise LinkError(f'{self.port}: {err}; resynchronised, coils reset') from None
        for reply, code in zip(replies, codes, strict=True):
            if isinstance(reply, proto.ErrorReply):
                self.counts.bad_replies += 1
                raise BoardReplyError(
                    f'{self.port}: the board answered request {code:02x} with error {reply.code}'
                )
        self.counts.requests += len(codes)
        return replies, stamp_ns

    def _read_frames(self, deadline: float, count: int) -> tuple[list[bytes], str, int]:
        """Read ``count`` reply frames: ``(payloads, '', host ns at the first frame's end)``.

        On failure the problem is ``_TIMEOUT`` (not all frames ended by the
        deadline) or what is wrong. Replies are accepted only when the bytes
        received since the request are exactly ``count`` valid COBS frames:
        garbage before them (it would merge into a frame), another frame or
        bytes after them (a late or foreign reply) make the exchange suspect.
        """
        got = bytearray()
        stamp_ns = 0
        while True:
            if self._clock() > deadline:
                self.counts.dropped_bytes += len(got)
                return [bytes(got)], _TIMEOUT, 0
            data = self._serial.read()
            if not data:
                continue
            got += data
            ends = got.count(0)
            if ends and not stamp_ns:
                stamp_ns = time.time_ns()  # the first reply (the sensors) is complete
            if ends < count:
                if len(got) > count * _MAX_REPLY:
                    return [bytes(got)], f'{len(got)} bytes without {count} frame ends', 0
                continue
            if ends > count or got[-1] != 0:
                return [bytes(got)], 'bytes after the reply frames (garbage or a late reply)', 0
            try:
                return [decode_frame(f) for f in bytes(got[:-1]).split(b'\x00')], '', stamp_ns
            except FrameError as err:
                return [bytes(got)], str(err), 0

    def _drain(self, deadline: float) -> None:
        """Read and drop bytes until the port is quiet for ``_QUIET_S`` (or ``deadline``).

        A board with another firmware may never be quiet (a V2x board streams):
        the deadline ends the drain, and the ping then fails.
        """
        quiet_until = self._clock() + _QUIET_S
        while self._clock() < min(quiet_until, deadline):
            data = self._serial.read()
            if data:
                self.counts.dropped_bytes += len(data)
                quiet_until = self._clock() + _QUIET_S

    def _resync(self, timeout: float) -> None:
        """End a half frame, drop stale bytes, ping until ``EE``; LinkError on no answer."""
        self.counts.resyncs += 1
        deadline = self._clock() + timeout
        self._serial.write(DELIMITER)
        while True:
            self._drain(deadline)
            if self.ping(min(0.25, max(deadline - self._clock(), 0.01))):
                self._drain(deadline + _QUIET_S)  # bytes after EE (none from a sound board)
                return
            if self._clock() > deadline:
                raise LinkError(
                    f'{self.port}: no answer to the ping (AA -> EE) within {timeout:g} s; '
                    f'expected a Maggy V4x board running the {FIRMWARE_NAME} '
                    '(docs/boards.md says how to flash it)'
                )

    def _recover(self) -> None:
        """Resynchronise, then reset the coils (best effort: never raises)."""
        try:
            self._resync(self.timeout + 1.2)  # a half frame stalls the board for 1 s
        except LinkError:
            pass
        self._safe_reset()

    def _safe_reset(self) -> None:
        """Send ``04`` and wait briefly for its reply; never raise."""
        try:
            self._serial.write(proto.request(proto.RESET))
            payloads, problem, _ = self._read_frames(self._clock() + self.timeout, 1)
        except LinkError:
            return
        if not problem and payloads == [bytes([proto.RESET])]:
            self.counts.resets += 1
            self.last_command = (0, 0)
