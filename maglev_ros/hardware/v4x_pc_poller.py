"""The driver's I/O loop for a V4x PC-control board, ROS-free: poll, command, reset.

:class:`V4xPcPoller` runs a :class:`~maglev_ros.hardware.v4x_pc_link.V4xPcLink`
at a fixed rate: each step is one :meth:`~V4xPcLink.cycle` (``01`` read the
sensors, ``02`` read the currents, ``03`` apply the pending command, in one
round trip), and its sample is handed to a callback in SI units (the node
publishes it). It has the interface of
:class:`~maglev_ros.hardware.board_link.BoardLink` that the driver node uses
(``send``, ``send_zero``, ``run``, ``close``, ``state``, ``counts``,
``applied``), so the node wires either the same way.

**Samples.** The field is the board's processed field (baseline and
feedthrough removed, x and y low-pass filtered: docs/boards.md), mT -> T; the
currents are the board's ADC reading, A, order x+, x-, y+, y-. Each sample is
stamped with the host's system clock (``time.time_ns``, the ROS time of a node
without simulated time) when the sensor reply had arrived, made strictly
increasing (a clock step back gives the previous stamp + 1 ns).

**Commands.** :meth:`send` stores the pair differences of the guard's counts;
the next step writes them (a command computed from a sample goes out with the
next step's requests: one poll period later at most). The latency from the
stamp of the newest sample handed on before the command arrived to the write
that carries it is measured per command (``health_values``).

**Coil resets (04).** The firmware has no watchdog. The poller resets the
coils when :meth:`send_zero` is called (the node: command timeout, disabled,
shutdown), after any error on the link (the link itself also resynchronises
and resets after a timeout or a bad reply), on every (re)connection
(``V4xPcLink.open``) and in :meth:`close`. After a reset the coils stay at zero
until a new command comes.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np

from .board_link import LINK_COUNTERS
from .command_guard import pair_differences
from .serial_link import Backoff, LinkError
from .v4x_pc_link import FIRMWARE_NAME, V4xPcLink

__all__ = ['DEFAULT_POLL_RATE', 'REPLY_TIMEOUT_S', 'V4xPcPoller']

DEFAULT_POLL_RATE = 1000.0  # Hz: above the lab host's 800 Hz, inside the board's round trip
#: s to wait for a step's replies: longer than the board's longest silence (its 160 ms
#: sensor reset), so only a board that stopped answering is a link error (and a reset)
REPLY_TIMEOUT_S = 0.25
_LATENCY_WINDOW = 2000  # commands kept for the latency percentiles
_CATCH_UP = 20  # steps behind the schedule that are made up (beyond: the schedule restarts)


class V4xPcPoller:
    """Poll a V4x PC-control board and send its commands (see the module docstring).

    Parameters
    ----------
    board : V4xPcLink
        The board's link (closed).
    backoff : Backoff
        Delays between reopen attempts after the link was lost.
    log
        Logger: ``info``, ``warning``, ``error`` (text, optional
        ``throttle_duration_sec``), as a ROS logger.
    poll_rate : float, optional
        Steps per second (0: as fast as the board answers).

    Attributes
    ----------
    state : str
        ``connecting``, ``waiting for board``, ``connected`` or ``disconnected``.
    counts : dict of str to int
        ``LINK_COUNTERS`` (``records``: samples handed on; ``commands_sent``:
        new commands written; ``io_errors``: link errors survived).
    applied : ndarray of int64, shape (4,)
        PWM counts last written, x+ x- y+ y-.
    last_info : str
        The last link error ('' if none).
    """

    n_values = 7  # Bx By Bz (T), then the 4 currents (A)

    def __init__(
        self,
        board: V4xPcLink,
        backoff: Backoff,
        log,
        *,
        poll_rate: float = DEFAULT_POLL_RATE,
    ) -> None:
        if not poll_rate >= 0:
            raise ValueError(f'poll_rate must be >= 0 Hz, got {poll_rate!r}')
        self.board = board
        self.backoff = backoff
        self.log = log
        self.poll_rate = float(poll_rate)
        self._period_ns = round(1e9 / poll_rate) if poll_rate else 0
        self.state = 'connecting'
        self.counts = dict.fromkeys(LINK_COUNTERS, 0)
        self.applied = np.zeros(4, dtype=np.int64)
        self.last_info = ''
        self._connections = 0
        self._io = threading.Lock()  # the board: one step, or close
        self._pending = threading.Lock()  # the command slot below
        self._command = (0, 0)
        self._fresh = False  # a command not written yet
        self._reset = False  # a 04 to send before the next step
        self._basis_ns = 0  # stamp of the newest sample when the command came
        self._last_stamp_ns = 0
        self.latencies_ns: deque[int] = deque(maxlen=_LATENCY_WINDOW)

    # -- connection ---------------------------------------------------------------------

    def open(self) -> None:
        """Open the link: ping, reset the coils (``V4xPcLink.open``).

        Raises
        ------
        LinkError
            If the port cannot be opened or the board does not answer the ping
            (the message names the port and the expected firmware).
        """
        with self._io:
            self.board.open()
        self._connected()

    def close(self) -> None:
        """Reset the coils (``04``, best effort) and close the port (idempotent).

        Waits for a step in progress (the I/O loop must be stopped first).
        """
        with self._io:
            self.board.close()
        if self.state == 'connected':
            self.state = 'disconnected'

    @property
    def resyncs(self) -> int:
        """Resynchronisations of the link after a timeout or a bad reply (not those of opening)."""
        return max(0, self.board.counts.resyncs - self._connections)

    @property
    def dropped_bytes(self) -> int:
        """Bytes the link read and threw away."""
        return self.board.counts.dropped_bytes

    # -- commands (any thread) --------------------------------------------------------------

    def send(self, counts: np.ndarray) -> None:
        """Apply PWM counts from a pairs guard at the next step.

        Parameters
        ----------
        counts : ndarray of int, shape (4,)
            ``(p_x, -p_x, p_y, -p_y)`` (``CommandGuard(..., pairs=True)``).
        """
        command = pair_differences(counts)
        with self._pending:
            self._command = command
            self._fresh = True
            self._basis_ns = self._last_stamp_ns

    def send_zero(self, zero: np.ndarray | None = None) -> None:
        """Reset the coils (``04``) before the next step; zero until a new command.

        Parameters
        ----------
        zero : ndarray, optional
            Ignored (the interface of ``BoardLink.send_zero``).
        """
        with self._pending:
            self._command = (0, 0)
            self._fresh = False
            self._reset = True

    # -- the I/O loop -------------------------------------------------------------------------

    def run(
        self,
        stop: threading.Event,
        publish: Callable[[np.ndarray, np.ndarray], None],
        send_zero: Callable[[], None] | None = None,
        read_interval: float = 0.0,
        alive: Callable[[], bool] = lambda: True,
    ) -> None:
        """Step until ``stop`` is set (or ``alive()`` turns false on an error).

        Parameters
        ----------
        stop : threading.Event
            Ends the loop.
        publish : callable
            ``publish(stamps_ns (1,), values (1, 7))``: field (T), currents (A).
        send_zero : callable, optional
            Unused: the poller resets the coils itself (``BoardLink.run``'s
            interface).
        read_interval : float, optional
            Unused (``BoardLink.run``'s interface).
        alive : callable, optional
            False once the process is shutting down: an error then ends the loop.
        """
        next_ns = time.monotonic_ns()
        while not stop.is_set():
            if not self.board.is_open and not self._reconnect(stop):
                continue
            if self._period_ns:
                now_ns = time.monotonic_ns()
                if next_ns > now_ns:
                    stop.wait((next_ns - now_ns) * 1e-9)
                # a fixed schedule: a step the OS woke late is made up by the next ones
                # (no wait while behind); more than _CATCH_UP steps behind starts it again
                next_ns += self._period_ns
                if now_ns - next_ns > _CATCH_UP * self._period_ns:
                    next_ns = now_ns + self._period_ns
            try:
                self._step(publish)
            except LinkError as err:
                if not alive():
                    break
                self._link_error(err)
            except Exception as err:  # noqa: BLE001 - reset the coils, then go on
                if not alive():  # a signal shut the process down mid-publish
                    break  # the caller closes the link (04)
                self.counts['io_errors'] += 1
                self.log.error(f'unexpected error in the board loop: {err!r}; coils reset')
                self._link_error(err, log=False)

    def _step(self, publish) -> None:
        with self._pending:
            (p_x, p_y), fresh, reset, basis = (
                self._command,
                self._fresh,
                self._reset,
                self._basis_ns,
            )
            self._fresh = self._reset = False
        with self._io:
            if not self.board.is_open:
                return
            if reset:
                self.board.reset()
            sent_ns = time.time_ns()
            step = self.board.cycle(p_x, p_y)
        self.applied = np.array([p_x, -p_x, p_y, -p_y], dtype=np.int64)
        if fresh:
            self.counts['commands_sent'] += 1
            if basis:
                self.latencies_ns.append(sent_ns - basis)
        stamp = max(step.stamp_ns, self._last_stamp_ns + 1)
        values = np.empty((1, self.n_values))
        values[0, :3] = step.field_mT * 1e-3
        values[0, 3:] = step.currents_A
        publish(np.array([stamp], dtype=np.int64), values)
        self._last_stamp_ns = stamp
        self.counts['records'] += 1

    def _link_error(self, err: Exception, *, log: bool = True) -> None:
        """Reset the coils after an error; close the link if even that fails."""
        self.last_info = str(err)
        if log:
            self.counts['io_errors'] += 1
            self.log.warning(f'{err}', throttle_duration_sec=1.0)
        with self._pending:  # the coils are reset: a new command is needed
            self._command, self._fresh, self._reset = (0, 0), False, False
        with self._io:
            try:
                self.board.reset()
                self.applied = np.zeros(4, dtype=np.int64)
                return
            except LinkError:
                self.board.close()  # best effort 04 again, then the port is closed
        self.state = 'disconnected'
        self.log.warning(f'{self.board.port}: link lost ({err}); reconnecting')

    def _reconnect(self, stop: threading.Event) -> bool:
        try:
            with self._io:
                self.board.open()  # pings, resets the coils
        except LinkError as err:
            self.state = 'waiting for board'
            delay = self.backoff.next_delay()
            self.log.warning(f'{err}; retrying in {delay:.1f} s', throttle_duration_sec=5.0)
            stop.wait(delay)
            return False
        self._connected()
        return True

    def _connected(self) -> None:
        self._connections += 1
        self.counts['reconnects'] = self._connections - 1
        self.backoff.reset()
        with self._pending:  # the link reset the coils: wait for a new command
            self._command, self._fresh, self._reset = (0, 0), False, False
        self.applied = np.zeros(4, dtype=np.int64)
        self.state = 'connected'
        self.log.info(f'connected to the {FIRMWARE_NAME} on {self.board.port}')

    # -- diagnostics ----------------------------------------------------------------------------

    def health_values(self) -> dict[str, str]:
        """Poll rate setting and command latency percentiles, for ``/diagnostics``."""
        lat = np.array(self.latencies_ns, dtype=float) * 1e-6
        rate = f'{self.poll_rate:g}' if self.poll_rate else 'as fast as the board answers'
        values = {'poll rate setting (Hz)': rate, 'link resets': str(self.board.counts.resets)}
        if lat.size:
            p50, p99 = np.percentile(lat, [50, 99])
            values['command latency p50 (ms)'] = f'{p50:.3f}'
            values['command latency p99 (ms)'] = f'{p99:.3f}'
        return values
