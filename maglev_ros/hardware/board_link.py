"""The driver's connection to the board, ROS-free: open, read, write, reconnect.

:class:`BoardLink` runs the driver's I/O loop on a :class:`SerialLink`: it
opens the port with exponential back-off, feeds what it reads to a
:class:`~maglev_ros.hardware.board_stream.BoardStream` and hands the decoded
samples to a callback (the node publishes them), writes command packets
(V2x), counts what happens and keeps the link state for ``/diagnostics``.
A lost link is closed and reopened; an unexpected error zeroes the coils
first. Messages go to a logger with the ``info`` / ``warning`` / ``error``
methods of a ROS logger (``throttle_duration_sec`` keyword).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from .board_stream import BoardStream, StreamOutput
from .packet import encode_command
from .serial_link import Backoff, LinkError, SerialLink
from .v4x_telemetry import Severity

__all__ = ['LINK_COUNTERS', 'BoardLink']

#: What the link counts: samples handed on, packets sent and not sent, link events.
LINK_COUNTERS = (
    'records',
    'commands_sent',
    'commands_unsent',
    'reconnects',
    'io_errors',
    'info_messages',
)


class BoardLink:
    """The board's serial link as the driver uses it (see the module docstring).

    Parameters
    ----------
    serial : SerialLink
        The port (closed).
    stream : BoardStream
        Decodes what is read.
    backoff : Backoff
        Delays between reopen attempts.
    log
        Logger: ``info``, ``warning``, ``error`` (text, optional
        ``throttle_duration_sec``).
    writes : bool
        The board takes commands (V2x); else :meth:`send` does nothing.

    Attributes
    ----------
    state : str
        ``connecting``, ``waiting for board``, ``connected`` or ``disconnected``.
    counts : dict of str to int
        ``LINK_COUNTERS``.
    applied : ndarray of int64, shape (4,)
        PWM counts of the last packet sent.
    last_info : str
        Text of the board's last info line (V4x).
    """

    def __init__(
        self, serial: SerialLink, stream: BoardStream, backoff: Backoff, log, writes: bool
    ) -> None:
        self.serial = serial
        self.stream = stream
        self.backoff = backoff
        self.log = log
        self.writes = bool(writes)
        self.state = 'connecting'
        self.counts = dict.fromkeys(LINK_COUNTERS, 0)
        self.applied = np.zeros(4, dtype=np.int64)
        self.last_info = ''
        self._connections = 0

    def send(self, counts: np.ndarray) -> None:
        """Send PWM counts as one packet (V2x); count it, or count it unsent.

        Not thread-safe: the caller serialises writes.

        Parameters
        ----------
        counts : ndarray of int64, shape (4,)
            PWM counts, x+ x- y+ y-.
        """
        if not self.writes:
            return
        try:
            self.serial.write(encode_command(counts))
        except LinkError:
            self.counts['commands_unsent'] += 1
            return
        self.stream.note_command(counts)  # a PWM the records may now show
        self.applied = counts
        self.counts['commands_sent'] += 1

    def send_zero(self, zero: np.ndarray) -> None:
        """Send the zero counts (V2x: a packet; the board applies them at once).

        Parameters
        ----------
        zero : ndarray of int64, shape (4,)
            The guard's zero counts.
        """
        self.send(zero)

    @property
    def resyncs(self) -> int:
        """Decoder resynchronisations over all connections."""
        return self.stream.resyncs

    @property
    def dropped_bytes(self) -> int:
        """Bytes the decoder dropped while resynchronising, over all connections."""
        return self.stream.dropped_bytes

    def health_values(self) -> dict[str, str]:
        """Values for ``/diagnostics`` beyond the common ones (none)."""
        return {}

    def run(
        self,
        stop: threading.Event,
        publish: Callable[[np.ndarray, np.ndarray], None],
        send_zero: Callable[[], None],
        read_interval: float = 0.0,
        alive: Callable[[], bool] = lambda: True,
    ) -> None:
        """Run the I/O loop until ``stop`` is set (or ``alive()`` turns false on an error).

        Parameters
        ----------
        stop : threading.Event
            Ends the loop.
        publish : callable
            ``publish(stamps_ns (n,), values (n, 3 N + 4))``: hand on n samples.
        send_zero : callable
            Sends zero currents (with the caller's lock): on connecting and
            after an unexpected error.
        read_interval : float, optional
            Shortest time between reads, s (0: read as data arrives).
        alive : callable, optional
            False once the process is shutting down: an error then ends the
            loop quietly (the caller zeroes the coils).
        """
        while not stop.is_set():
            if not self.serial.is_open:
                try:
                    self.serial.open()
                except LinkError as err:
                    self.state = 'waiting for board'
                    delay = self.backoff.next_delay()
                    self.log.warning(
                        f'{err}; retrying in {delay:.1f} s', throttle_duration_sec=5.0
                    )
                    stop.wait(delay)
                    continue
                self._connected(send_zero)
            try:
                data = self.serial.read()
                if data:
                    read_at = time.monotonic()
                    # system time: the ROS time of a node without sim time
                    self._handle(self.stream.feed(data, time.time_ns()), publish)
                    if read_interval:  # let bursts collect: one read, decode, publish for several
                        stop.wait(read_interval - (time.monotonic() - read_at))
            except LinkError as err:
                self._disconnected(f'link lost: {err}')
            except Exception as err:  # noqa: BLE001 - zero the coils, then reconnect
                if not alive():  # a signal shut the process down mid-publish:
                    break  # the caller zeroes the coils
                self.counts['io_errors'] += 1
                self.log.error(
                    f'unexpected error on the board link: {err!r}; zeroing and reconnecting'
                )
                send_zero()
                self._disconnected('error')
                stop.wait(self.backoff.next_delay())

    def close(self) -> None:
        """Close the port (idempotent)."""
        self.serial.close()

    def _connected(self, send_zero: Callable[[], None]) -> None:
        self._connections += 1
        self.counts['reconnects'] = self._connections - 1
        self.backoff.reset()
        self.stream.connect()
        self.state = 'connected'
        self.log.info(f'connected to {self.serial.port}')
        send_zero()  # a known state; applied once the board's loop runs

    def _disconnected(self, reason: str) -> None:
        self.serial.close()
        self.stream.disconnect()
        self.state = 'disconnected'
        self.log.warning(f'{self.serial.port}: {reason}')

    def _handle(self, output: StreamOutput, publish) -> None:
        """Log the board's info lines, hand on the samples of one read."""
        for info in output.infos:
            self.counts['info_messages'] += 1
            self.last_info = info.text
            if info.severity >= Severity.WARN:
                self.log.warning(f'board: {info.text}')
            else:
                self.log.info(f'board: {info.text}')
        if len(output):
            publish(output.stamps_ns, output.values)
            self.counts['records'] += len(output)
