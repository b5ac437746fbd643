"""The board stream: bytes from the board to stamped samples in SI units.

:class:`BoardStream` turns what the driver reads from the port into samples
ready to publish, for either firmware family:

* **decode**: V2x binary records (:class:`~maglev_ros.hardware.v2x_stream.RecordDecoder`,
  resynchronising after damage) or V4x text lines
  (:class:`~maglev_ros.hardware.v4x_telemetry.TelemetryStream`, whose
  informational lines are passed on for logging);
* **units**: fields mT -> T; currents in A (V2x: the current implied by the
  applied PWM through the :class:`~maglev_ros.hardware.scaling.CurrentScaling`;
  V4x: the measured current);
* **board clock**: each read is one observation of the board's sample clock
  against the host's (:class:`~maglev_ros.hardware.board_clock.BoardClock`),
  which maps board times to host stamps (ns);
* **catch-up after (re)connection**: see :meth:`BoardStream.feed`.

It does no I/O and reads no clock: the caller passes each read's bytes and
host time, and calls :meth:`~BoardStream.connect` / :meth:`~BoardStream.disconnect`
as the link comes and goes. Not thread-safe (the driver's I/O thread owns it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .board_clock import BoardClock
from .scaling import CurrentScaling
from .v2x_stream import BURST_RECORDS, SAMPLE_PERIOD_US, DecoderStats, RecordDecoder, pack_records
from .v4x_telemetry import InfoMessage, TelemetryStream

__all__ = [
    'BURST_PERIOD_S',
    'FIRMWARES',
    'MAX_HELD_RECORDS',
    'BoardStream',
    'StreamOutput',
    'caught_up_records',
]

FIRMWARES = ('v2x', 'v4x')
BURST_PERIOD_S = 0.001  # s between the board's bursts (V2x; V4x lines come at most as often)
MAX_HELD_RECORDS = 25_000  # 5 s at 5 kHz: a link that never looks caught up publishes anyway


def caught_up_records(read_interval: float) -> int:
    """Return how many records a read brings when the link keeps up.

    The bursts of one read interval (at least one 1 ms burst), one more for
    timing jitter, and the record held back for confirmation.

    Parameters
    ----------
    read_interval : float
        Shortest time between reads of the port, s (0: every burst).

    Returns
    -------
    int
        More than this in one read means a backlog.
    """
    bursts = max(1, math.ceil(read_interval / BURST_PERIOD_S - 1e-9))
    return BURST_RECORDS * (bursts + 1) + 1


@dataclass(frozen=True)
class StreamOutput:
    """What one read yields.

    Attributes
    ----------
    stamps_ns : ndarray of int64, shape (n,)
        Host time of each sample, ns (strictly increasing).
    values : ndarray of float64, shape (n, 3 N + 4)
        Each sensor's field x y z (T), then the 4 coil currents (A).
    infos : tuple of InfoMessage
        The board's informational lines (V4x), to log.
    """

    stamps_ns: np.ndarray
    values: np.ndarray
    infos: tuple[InfoMessage, ...] = ()

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])


class BoardStream:
    """Decode, convert and stamp the board's samples (see the module docstring).

    Parameters
    ----------
    firmware : {'v2x', 'v4x'}
        Firmware family: binary records or text lines.
    n_sensors : int
        Sensors per record or line.
    scaling : CurrentScaling
        PWM counts to current (V2x).
    confirm_records : bool, optional
        V2x: hold the newest record of each read until the next confirms its
        boundary (see :mod:`maglev_ros.hardware.v2x_stream`).
    read_interval : float, optional
        Shortest time between the caller's reads, s: sets how many records a
        read brings once the link has caught up.

    Raises
    ------
    ValueError
        On an unknown firmware.
    """

    def __init__(
        self,
        firmware: str,
        n_sensors: int,
        scaling: CurrentScaling,
        *,
        confirm_records: bool = True,
        read_interval: float = 0.0,
    ) -> None:
        if firmware not in FIRMWARES:
            raise ValueError(f"firmware must be 'v2x' or 'v4x', got {firmware!r}")
        self.firmware = firmware
        self.n_sensors = n_sensors
        self.scaling = scaling
        self.confirm_records = bool(confirm_records)
        self.n_values = 3 * n_sensors + 4
        self.caught_up_records = caught_up_records(read_interval)
        self._earlier = {'resyncs': 0, 'dropped_bytes': 0}  # of earlier connections
        self.decoder = RecordDecoder(n_sensors, confirm=self.confirm_records)
        self.connect()

    # -- link state -------------------------------------------------------------

    def connect(self) -> None:
        """Start a connection: fresh decoders and board clock, catching up.

        The board may have been power-cycled: its clock starts again.
        """
        self.decoder = RecordDecoder(self.n_sensors, confirm=self.confirm_records)
        self.telemetry = TelemetryStream(self.n_sensors)
        self.clock = BoardClock()
        self.catching_up = True  # until a read brings no backlog
        self._held: list[tuple[np.ndarray, np.ndarray]] = []  # samples kept meanwhile

    def disconnect(self) -> None:
        """End a connection: keep its decoder's counts, drop its partial record."""
        self._earlier['resyncs'] += self.decoder.stats.resyncs
        self._earlier['dropped_bytes'] += self.decoder.stats.dropped_bytes
        self.decoder = RecordDecoder(self.n_sensors, confirm=self.confirm_records)

    def note_command(self, counts: np.ndarray) -> None:
        """Tell the V2x decoder the PWM counts of a command sent (see ``RecordDecoder``).

        Parameters
        ----------
        counts : ndarray of int, shape (4,)
            PWM counts sent, x+ x- y+ y-.
        """
        self.decoder.note_command(counts)

    @property
    def decoder_stats(self) -> DecoderStats:
        """Counters of the record decoder of the current connection (V2x)."""
        return self.decoder.stats

    @property
    def buffered(self) -> int:
        """Bytes the V2x decoder holds (a partial or unconfirmed record)."""
        return self.decoder.buffered

    @property
    def resyncs(self) -> int:
        """V2x resynchronisations over all connections."""
        return self._earlier['resyncs'] + self.decoder.stats.resyncs

    @property
    def dropped_bytes(self) -> int:
        """V2x bytes dropped while resynchronising, over all connections."""
        return self._earlier['dropped_bytes'] + self.decoder.stats.dropped_bytes

    def warm_up(self) -> None:
        """Run a decoder once on made-up records, before any I/O.

        Its numba kernels load (or compile) on first use, 0.5 to 1.5 s holding
        the GIL; in the I/O thread that stall would overflow the publishers'
        history with the backlog of the board's records.
        """
        decoder = RecordDecoder(self.n_sensors, confirm=self.confirm_records)
        stamps = SAMPLE_PERIOD_US * np.arange(2 * BURST_RECORDS)
        zeros = np.zeros((stamps.size, self.n_sensors, 3))
        decoder.feed(pack_records(stamps, zeros, np.zeros((stamps.size, 4))))

    # -- reading ----------------------------------------------------------------

    def feed(self, data: bytes, host_ns: int) -> StreamOutput:
        """Decode one read and return the samples to publish now.

        After a (re)connection the first reads may bring a backlog (the board
        streamed while nobody read: a busy start-up, a stale OS buffer). The
        newest record of such a read is old, so its observation would put the
        clock's first offset late by the backlog's age, and correcting that
        later would hold stamps back. Until a read brings no more than the
        records a read normally brings (:attr:`caught_up_records`: the link
        has caught up), samples are therefore kept, not stamped; then all of
        them are stamped with the caught-up clock and returned. Nothing is
        lost, the first stamps are right, the catch-up costs latency only
        once. A link that never looks caught up returns its samples once
        ``MAX_HELD_RECORDS`` are kept.

        Parameters
        ----------
        data : bytes
            What one read of the port returned.
        host_ns : int
            Host (system) time of the read, ns: the ROS time of a node
            without simulated time.

        Returns
        -------
        StreamOutput
            Stamped samples (possibly none) and the board's info lines.
        """
        if self.firmware == 'v2x':
            batch = self.decoder.feed(data)
            if not len(batch):
                return self._nothing()
            n = len(batch)
            values = np.empty((n, self.n_values))  # each field (T), then the currents (A)
            np.multiply(batch.field_mT.reshape(n, -1), 1e-3, out=values[:, :-4], dtype=np.float64)
            self.scaling.to_current(batch.pwm, out=values[:, -4:])
            return self._deliver(batch.time_us, values, host_ns)
        samples, infos = [], []
        for item in self.telemetry.feed(data):
            (infos if isinstance(item, InfoMessage) else samples).append(item)
        if not samples:
            return self._nothing(tuple(infos))
        board_us = np.array([round(s.time * 1e6) for s in samples], dtype=np.int64)
        field_t = np.stack([s.field_mT for s in samples]).reshape(len(samples), -1) * 1e-3
        currents = np.stack([s.current for s in samples])
        return self._deliver(board_us, np.hstack([field_t, currents]), host_ns, tuple(infos))

    def _deliver(
        self,
        board_us: np.ndarray,
        values: np.ndarray,
        host_ns: int,
        infos: tuple[InfoMessage, ...] = (),
    ) -> StreamOutput:
        """Observe the board clock; stamp the samples unless catching up (see ``feed``)."""
        self.clock.observe(int(board_us[-1]), host_ns)
        if self.catching_up:
            self._held.append((board_us, values))
            held = sum(len(b) for b, _ in self._held)
            if len(board_us) > self.caught_up_records and held < MAX_HELD_RECORDS:
                return self._nothing(infos)
            self.catching_up = False
            board_us = np.concatenate([b for b, _ in self._held])
            values = np.concatenate([v for _, v in self._held])
            self._held.clear()
        return StreamOutput(self.clock.to_host(board_us), values, infos)

    def _nothing(self, infos: tuple[InfoMessage, ...] = ()) -> StreamOutput:
        return StreamOutput(np.empty(0, np.int64), np.empty((0, self.n_values)), infos)
