"""The driver's board session, ROS-free: link thread, decoding, command guard, timeouts.

:class:`BoardSession` is everything the driver node does between the serial
port and its topics, without ROS:

* **the link thread**: it runs the board's I/O loop
  (:class:`~maglev_ros.hardware.board_link.BoardLink` on a V2x or V4x stream,
  or :class:`~maglev_ros.hardware.v4x_pc_poller.V4xPcPoller` on a V4x
  PC-control board) and queues the samples it yields;
* **the samples to publish**: :meth:`BoardSession.take` hands over every
  sample queued since the previous call, in order, as one block (the node
  calls it on a timer and publishes the block); a queue left untaken beyond
  ``max_backlog`` samples drops its oldest ones, counted (the link thread never
  waits for the publisher);
* **commands**: :meth:`BoardSession.command` passes the commanded currents
  through the :class:`~maglev_ros.hardware.command_guard.CommandGuard` and
  writes what it allows; :meth:`BoardSession.reject` counts a command that
  could not even be read; :meth:`BoardSession.set_enabled` and
  :meth:`BoardSession.check_timeout` zero the coils when disabled or when no
  valid command came for ``command_timeout`` s;
* **shutdown**: :meth:`BoardSession.close` stops the link thread, zeroes the
  coils (V2x: a zero packet; V4x PC control: ``04``) and closes the port.

Warnings (rejected, clamped or ignored commands, timeouts) go to the logger
given, throttled, as the link's own messages do. The session reads the
monotonic clock for the command timeout and the system clock for the
samples' stamps (in the link); all its methods may be called from any thread.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..health import Health
from .board_link import BoardLink
from .board_stream import BoardStream
from .command_guard import CommandGuard, GuardDecision
from .driver_config import DriverConfig
from .driver_health import FIELD_KINDS, DriverHealth, driver_counters
from .serial_link import Backoff, SerialLink
from .v4x_pc_link import V4xPcLink
from .v4x_pc_poller import REPLY_TIMEOUT_S, V4xPcPoller

__all__ = ['GIL_SWITCH_S', 'MAX_BACKLOG', 'WARN_THROTTLE_S', 'BoardSession', 'SampleBlock']

WARN_THROTTLE_S = 1.0  # s between repeated warnings of one kind
GIL_SWITCH_S = 0.0002  # s, the interpreter's switch interval while a V4x PC board is polled
MAX_BACKLOG = 50_000  # samples queued for the publisher at most (10 s at 5 kHz)


@dataclass(frozen=True, slots=True)
class SampleBlock:
    """Samples to publish.

    Attributes
    ----------
    stamps_ns : ndarray of int64, shape (n,)
        Stamp of each sample, ns (system clock, strictly increasing).
    values : ndarray of float64, shape (n, 3 N + 4)
        Each sensor's field x y z (T), then the coil currents x+ x- y+ y- (A).
    """

    stamps_ns: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])


class BoardSession:
    """One board, from port to samples and from commands to PWM (module docstring).

    Parameters
    ----------
    config : DriverConfig
        The driver's validated settings.
    log
        Logger: ``info``, ``warning``, ``error`` (text, optional
        ``throttle_duration_sec``), as a ROS logger.
    max_backlog : int, optional
        Samples queued for :meth:`take` at most; beyond, the oldest are
        dropped (``samples_dropped``).

    Attributes
    ----------
    guard : CommandGuard
        What reaches the coils.
    link : BoardLink or V4xPcPoller
        The board's I/O loop.
    stream : BoardStream or None
        The decoder of a streaming board (None for V4x PC control).
    samples_dropped : int
        Samples dropped because :meth:`take` was not called in time.
    """

    def __init__(self, config: DriverConfig, log, *, max_backlog: int = MAX_BACKLOG) -> None:
        self.log = log
        self.max_backlog = int(max_backlog)
        self._lock = threading.Lock()  # the guard and the link's writes
        self.guard = CommandGuard(
            config.scaling,
            config.current_limit,
            config.command_timeout,
            enabled=config.start_enabled,
            read_only=config.firmware == 'v4x',
            pairs=config.firmware == 'v4x_pc',
        )
        self.config = config
        backoff = Backoff(config.reconnect_min_delay, config.reconnect_max_delay)
        if config.firmware == 'v4x_pc':
            self.stream = None
            board = V4xPcLink(config.port, timeout=REPLY_TIMEOUT_S)
            self.link = V4xPcPoller(board, backoff, log, poll_rate=config.poll_rate)
        else:
            self.stream = BoardStream(
                config.firmware,
                config.n_sensors,
                config.scaling,
                confirm_records=config.confirm_records,
                read_interval=config.read_interval,
            )
            serial = SerialLink(config.port, config.baudrate)
            writes = config.firmware == 'v2x'
            self.link = BoardLink(serial, self.stream, backoff, log, writes=writes)
            self.stream.warm_up()  # compiled kernels load now, not in the link thread
        self.health = DriverHealth(config.firmware, time.monotonic())
        self.samples_dropped = 0
        self._queue: deque[SampleBlock] = deque()
        self._queued = 0
        self._queue_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='maglev-board-io', daemon=True)
        self._switch_interval: float | None = None
        self._closed = False

    # -- settings and state ---------------------------------------------------------

    def configure(self, config: DriverConfig) -> None:
        """Apply run-time settings: the current limit and the command timeout.

        Parameters
        ----------
        config : DriverConfig
            The validated settings (the others are fixed at start).
        """
        with self._lock:
            self.guard.configure(config.current_limit, config.command_timeout)
        self.config = config

    @property
    def enabled(self) -> bool:
        """Whether commands are applied (else zero currents are sent)."""
        return self.guard.enabled

    @property
    def counters(self) -> dict[str, int]:
        """Records, commands sent/rejected/clamped/unsent/ignored, timeouts, link events."""
        return driver_counters(self.link, self.guard) | {'samples_dropped': self.samples_dropped}

    @property
    def polled(self) -> bool:
        """Whether the board is polled (V4x PC control) rather than streaming."""
        return self.stream is None

    def describe(self) -> str:
        """One line for the log: firmware, port, sensors, field kind, scaling, limit, state."""
        cfg = self.config
        polled = f', polled at {cfg.poll_rate:g} Hz' if self.polled and cfg.poll_rate else ''
        return (
            f'{cfg.firmware} board on {cfg.port}, {cfg.n_sensors} sensor(s), publishing fields: '
            f'{FIELD_KINDS[cfg.firmware]}{polled}; '
            f'{cfg.scaling.counts_per_ampere:.1f} counts/A, limit {cfg.current_limit:.3f} A, '
            f'{"enabled" if self.enabled else "disabled"}'
        )

    # -- the link thread ------------------------------------------------------------

    def open(self) -> None:
        """Open the board and start the link thread (idempotent; not after :meth:`close`).

        V4x PC control pings the board here; a streaming board's port is
        opened (and reopened) by the link thread, with back-off.

        Raises
        ------
        LinkError
            V4x PC control: the port cannot be opened or nothing answers the
            ping (the message names the port and the firmware expected).
        """
        if self._thread.ident is not None or self._closed:
            return
        if self.polled:
            self.link.open()
            # each step waits for the board's reply: a thread holding the GIL would hand
            # it back only after the switch interval (default 5 ms), capping the poll rate
            self._switch_interval = sys.getswitchinterval()
            sys.setswitchinterval(min(self._switch_interval, GIL_SWITCH_S))
        self._thread.start()

    def _run(self) -> None:
        self.link.run(self._stop, self._queue_samples, self._zero, self.config.read_interval)

    def _queue_samples(self, stamps_ns: np.ndarray, values: np.ndarray) -> None:
        """Queue a read's samples for :meth:`take` (the link thread)."""
        with self._queue_lock:
            self._queue.append(SampleBlock(stamps_ns, values))
            self._queued += len(stamps_ns)
            while self._queued > self.max_backlog and len(self._queue) > 1:
                dropped = len(self._queue.popleft())
                self._queued -= dropped
                self.samples_dropped += dropped

    def take(self) -> SampleBlock | None:
        """Every sample queued since the previous call, in order, or None if there is none.

        Returns
        -------
        SampleBlock or None
            Stamps (n,) ns and values (n, 3 N + 4): fields (T), currents (A).
        """
        with self._queue_lock:
            if not self._queue:
                return None
            blocks = list(self._queue)
            self._queue.clear()
            self._queued = 0
        if len(blocks) == 1:
            return blocks[0]
        return SampleBlock(
            np.concatenate([b.stamps_ns for b in blocks]),
            np.concatenate([b.values for b in blocks]),
        )

    # -- commands -------------------------------------------------------------------

    def command(self, currents: Sequence[float] | np.ndarray) -> None:
        """Pass one command through the guard and write what it allows.

        Parameters
        ----------
        currents : array_like, shape (4,)
            Commanded currents x+ x- y+ y-, A (another shape, NaN or an
            infinite value: rejected, nothing is written).
        """
        with self._lock:
            decision = self.guard.command(currents, time.monotonic_ns())
            if decision.counts is not None:
                self.link.send(decision.counts)
        self._warn(decision)

    def reject(self, reason: str) -> None:
        """Count and report a command that could not be read (nothing is written).

        Parameters
        ----------
        reason : str
            What was wrong with it.
        """
        with self._lock:
            decision = self.guard.reject(reason)
        self._warn(decision)

    def set_enabled(self, enabled: bool) -> None:
        """Enable or disable the coils (disabling zeroes them at once).

        Parameters
        ----------
        enabled : bool
            The new state.
        """
        with self._lock:
            if self.guard.set_enabled(enabled) is not None:
                self.link.send_zero(self.guard.zero)

    def check_timeout(self) -> None:
        """Zero the coils if no valid command came for ``command_timeout`` s (once)."""
        with self._lock:
            age = self.guard.check_timeout(time.monotonic_ns())
            if age is None:
                return
            self.link.send_zero(self.guard.zero)
        self.log.warning(
            f'no valid command for {age:.3f} s > {self.guard.command_timeout} s: '
            'zero currents sent',
            throttle_duration_sec=WARN_THROTTLE_S,
        )

    def _zero(self) -> None:
        with self._lock:
            self.link.send_zero(self.guard.zero)

    def _warn(self, decision: GuardDecision) -> None:
        if decision.warning:
            self.log.warning(decision.warning, throttle_duration_sec=WARN_THROTTLE_S)

    # -- diagnostics and shutdown ------------------------------------------------------

    def report(self) -> Health:
        """Return the board's health for ``/diagnostics`` (rates since the previous report).

        Returns
        -------
        Health
            Link state, rates, counters (``DriverHealth.report``), and the
            samples dropped for a late publisher.
        """
        health = self.health.report(self.link, self.guard, time.monotonic())
        values = dict(health.values) | {'samples dropped': str(self.samples_dropped)}
        return Health(health.level, health.message, values)

    def close(self) -> None:
        """Stop the link thread, zero the coils and close the port (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread.ident is not None:
            self._thread.join(timeout=2.0)
        if not self.polled and self.link.writes and self.link.serial.is_open:
            self._zero()
        self.link.close()  # V4x PC control: 04 first
        if self._switch_interval is not None:
            sys.setswitchinterval(self._switch_interval)
            self._switch_interval = None
