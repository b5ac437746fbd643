"""The V2x board as a plant of the control loop: its samples read, its coils commanded.

:class:`BoardPlant` puts the driver's ROS-free core behind the
:class:`~maglev_ros.loop.Plant` protocol, in the loop's own thread:

* **read**: what the port holds (:class:`~maglev_ros.hardware.SerialLink`)
  is decoded, converted to SI units and stamped on the host's clock
  (:class:`~maglev_ros.hardware.board_stream.BoardStream`: the V2x binary
  records, the board's sample clock mapped onto the host's), until at least
  ``burst`` samples came: the board's 5 kHz stream then paces the loop at
  ``sample_rate / burst`` commands per second;
* **write**: a command passes the command guard
  (:class:`~maglev_ros.hardware.CommandGuard`: finite, clamped to
  ``current_limit``, scaled to PWM counts) and goes out as one packet
  (:class:`~maglev_ros.hardware.board_link.BoardLink`);
* **close**, and any error of the link: the coils are set to zero current
  (a zero packet) and the port is closed.

A session does not reconnect: a lost link ends it (``crashed``, the reason
named), as a lost magnet ends a simulation. Another board (the V4x
PC-control firmware's request/response link) is another class with the same
four members (``read``, ``write``, ``close``, ``sample_rate``/``n_inputs``/
``lockstep``): the loop does not know which it runs.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from ..hardware.board_link import BoardLink
from ..hardware.board_stream import BoardStream
from ..hardware.command_guard import CommandGuard
from ..hardware.scaling import BOARD_COIL_RESISTANCE, BOARD_SUPPLY_VOLTAGE, CurrentScaling
from ..hardware.serial_link import Backoff, LinkError, SerialLink
from .plant import SampleBlock

__all__ = ['BOARD_SAMPLE_RATE', 'BoardPlant']

BOARD_SAMPLE_RATE = 5000.0  # Hz, the V2x firmware's sample rate
STALL_S = 5.0  # s without a sample from an open link before the session is ended
#: s for the first sample after the port opens (a virtual board's physics compiles first)
FIRST_SAMPLE_S = 60.0


class BoardPlant:
    """A V2x board on a serial port, read and commanded by the loop (module docstring).

    Parameters
    ----------
    port : str
        Serial device (a board, or a virtual board's link).
    n_sensors : int
        Sensors per record.
    burst : int
        Samples a read waits for (the loop's period in samples).
    current_limit : float
        Largest commanded |current|, A (0: the scaling's full scale).
    command_timeout : float
        s without a valid command before the guard sends zero currents.
    supply_voltage, coil_resistance : float
        The V2x scaling (V, ohm); ``counts_per_ampere`` > 0 overrides them.
    counts_per_ampere : float
        PWM counts per A (0: from voltage and resistance).
    confirm_records : bool
        Hold each read's newest record until the next confirms it (False: the
        lowest latency, what a closed loop wants).
    read_interval : float
        Shortest time between reads of the port, s (0: as data arrive; an
        open-loop recording reads every 2 ms for less CPU).
    baudrate : int
        Baud rate (ignored by USB CDC).
    serial : SerialLink, optional
        The link (default one on ``port``).
    clock : callable, optional
        Host time, ns (default ``time.time_ns``: ROS time without sim time).

    Attributes
    ----------
    counters : dict of str to int
        ``records``, ``commands_sent``, ``commands_unsent``,
        ``commands_clamped``, ``commands_rejected``, ``timeouts``,
        ``resyncs``, ``dropped_bytes``.
    """

    lockstep = False
    sample_rate = BOARD_SAMPLE_RATE
    n_inputs = 4

    def __init__(
        self,
        port: str,
        n_sensors: int,
        burst: int = 1,
        current_limit: float = 0.0,
        command_timeout: float = 0.1,
        supply_voltage: float = BOARD_SUPPLY_VOLTAGE,
        coil_resistance: float = BOARD_COIL_RESISTANCE,
        counts_per_ampere: float = 0.0,
        confirm_records: bool = False,
        read_interval: float = 0.0,
        baudrate: int = 9600,
        serial: SerialLink | None = None,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        if isinstance(burst, bool) or not isinstance(burst, int) or burst < 1:
            raise ValueError(f'burst must be an integer >= 1, got {burst!r}')
        if counts_per_ampere:
            scaling = CurrentScaling(counts_per_ampere)
        else:
            scaling = CurrentScaling.from_supply(supply_voltage, coil_resistance)
        self.port = port
        self.n_sensors = int(n_sensors)
        self.burst = burst
        self.scaling = scaling
        self.guard = CommandGuard(
            scaling, current_limit or scaling.max_current, command_timeout, enabled=True
        )
        self.read_interval = float(read_interval)
        self.stream = BoardStream(
            'v2x',
            self.n_sensors,
            scaling,
            confirm_records=confirm_records,
            read_interval=self.read_interval,
        )
        self.stream.warm_up()  # the decoder's kernels load now, not in the first read
        log = logging.getLogger('maglev_ros.board')
        self.link = BoardLink(
            serial or SerialLink(port, baudrate), self.stream, Backoff(0.2, 5.0), _Log(log), True
        )
        self.clock = clock
        self._n_fields = 3 * self.n_sensors
        self._index = 0
        self._first_ns: int | None = None
        self._read_at = 0.0
        self._closed = False

    @property
    def current_limit(self) -> float:
        """The guard's current limit, A."""
        return self.guard.current_limit

    @property
    def counters(self) -> dict[str, int]:
        """What the link, the guard and the decoder counted (see the class docstring)."""
        link, guard = self.link.counts, self.guard.counters
        return {
            'records': link['records'],
            'commands_sent': link['commands_sent'],
            'commands_unsent': link['commands_unsent'],
            'commands_clamped': guard['commands_clamped'],
            'commands_rejected': guard['commands_rejected'],
            'timeouts': guard['timeouts'],
            'resyncs': self.link.resyncs,
            'dropped_bytes': self.link.dropped_bytes,
        }

    def metadata(self, prefix: str = 'maglev_driver') -> dict[str, object]:
        """Return the settings in force as flat bag metadata (``<prefix>.<name>``).

        Parameters
        ----------
        prefix : str
            Key prefix (the driver node's name).
        """
        return {
            f'{prefix}.{k}': v
            for k, v in (
                ('port', self.port),
                ('firmware', 'v2x'),
                ('n_sensors', self.n_sensors),
                ('counts_per_ampere', self.scaling.counts_per_ampere),
                ('current_limit', self.current_limit),
                ('command_timeout', self.guard.command_timeout),
                ('start_enabled', True),
                ('confirm_records', self.stream.confirm_records),
                ('read_interval', self.read_interval),
                ('control_burst', self.burst),
            )
        }

    def open(self) -> BoardPlant:
        """Open the port and send zero currents (a known state).

        Returns
        -------
        BoardPlant
            ``self``.

        Raises
        ------
        LinkError
            If the port cannot be opened (the message names it).
        """
        serial = self.link.serial
        if not serial.is_open:
            serial.open()
            self.stream.connect()
            # no catch-up hold: the loop answers samples as they come (a held backlog
            # leaves the magnet uncontrolled); the board clock's fit corrects the stamps
            self.stream.catching_up = False
            self.link.state = 'connected'
            self.link.send_zero(self.guard.zero)
        return self

    def read(self) -> SampleBlock:
        """Wait for at least ``burst`` samples; return them (a crashed block on a failure)."""
        if self._closed:
            return self._failed('the board link is closed')
        stamps, values, got = [], [], 0
        last = time.monotonic()
        try:
            self.open()
            while got < self.burst:
                if self.read_interval:  # let bursts collect: one read for several
                    wait = self._read_at + self.read_interval - time.monotonic()
                    if wait > 0:
                        time.sleep(wait)
                    self._read_at = time.monotonic()
                data = self.link.serial.read()
                now = time.monotonic()
                if not data:
                    wait = STALL_S if self._first_ns is not None else FIRST_SAMPLE_S
                    if now - last > wait:
                        return self._failed(f'no sample from the board for {wait:g} s')
                    self._check_timeout()
                    continue
                out = self.stream.feed(data, self.clock())
                if len(out):
                    last = now
                    stamps.append(out.stamps_ns)
                    values.append(out.values)
                    got += len(out)
                    self.link.counts['records'] += len(out)
        except LinkError as err:
            return self._failed(f'the board link failed: {err}')
        stamps_ns = np.concatenate(stamps)
        v = np.concatenate(values)
        n = stamps_ns.shape[0]
        if self._first_ns is None:
            self._first_ns = int(stamps_ns[0])
        index = np.arange(self._index, self._index + n, dtype=np.int64)
        self._index += n
        return SampleBlock(
            index=index,
            times=(stamps_ns - self._first_ns) * 1e-9,
            stamps_ns=stamps_ns,
            readings=v[:, : self._n_fields],
            currents=v[:, self._n_fields :],
            valid=np.ones(n, dtype=bool),
        )

    def write(self, command: np.ndarray, stamp_ns: int) -> None:
        """Pass ``command`` through the guard and send it (nothing for a rejected one).

        Parameters
        ----------
        command : ndarray, shape (4,)
            Coil currents, A, order x+, x-, y+, y-.
        stamp_ns : int
            Stamp of the sample the command answers, ns.
        """
        decision = self.guard.command(command, time.monotonic_ns())
        if decision.counts is not None and not self._closed:
            self.link.send(decision.counts)

    def close(self) -> None:
        """Send zero currents and close the port (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self.link.serial.is_open:
            self.link.send_zero(self.guard.zero)
        self.link.close()

    def _check_timeout(self) -> None:
        if self.guard.check_timeout(time.monotonic_ns()) is not None:
            self.link.send_zero(self.guard.zero)

    def _failed(self, reason: str) -> SampleBlock:
        """Zero the coils (if the link still takes it) and return an empty, crashed block."""
        try:
            if self.link.serial.is_open:
                self.link.send_zero(self.guard.zero)
        finally:
            self.link.close()
            self._closed = True
        return SampleBlock(
            index=np.empty(0, dtype=np.int64),
            times=np.empty(0),
            stamps_ns=np.empty(0, dtype=np.int64),
            readings=np.empty((0, self._n_fields)),
            currents=np.empty((0, 4)),
            valid=np.empty(0, dtype=bool),
            crashed=True,
            reason=reason,
        )


class _Log:
    """A :mod:`logging` logger with the ROS logger's ``throttle_duration_sec`` keyword."""

    def __init__(self, log: logging.Logger) -> None:
        self._log = log

    def info(self, text: str, **_) -> None:
        self._log.info(text)

    def warning(self, text: str, **_) -> None:
        self._log.warning(text)

    def error(self, text: str, **_) -> None:
        self._log.error(text)
