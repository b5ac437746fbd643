"""V2x sample records: the layout, and a streaming decoder for the unframed stream.

One record, little-endian, for N sensors (``4 + 12 N + 8`` bytes)::

    uint32 timestamp (us since boot, wraps at 2**32)
    float32 Bx, By, Bz of sensor 0 .. N-1 (mT)
    int16 PWM x+, x-, y+, y- (counts)

The board writes them in bursts of 5 with no start marker, length or
checksum, so the decoder finds record boundaries from invariants:

* consecutive timestamps differ by ``min_step_us .. max_step_us``
  (default 100 .. 10 000 us; the board samples every 200 us, so a step
  outside this range means a lost boundary or a stall);
* every field component satisfies ``|B| <= max_field_mT`` (default
  1000 mT = 1 T: Hall sensors used on the board saturate at 100 to 200 mT;
  the comparison also rejects NaN and infinity);
* every PWM value lies in -4096 .. 4096.

Locking (first start, or after a lost boundary) needs ``lock_records``
(default 4) consecutive records that satisfy all three invariants; the
lock then extends backwards, record by record, to the latest plausible
record (directly adjacent, or before a damaged stretch) whose timestamp
steps correctly into it, so that a damaged record costs only itself even
when fewer than ``lock_records`` undamaged records separate it from the
start of the stream or from another damaged record (within a window of
``4 * lock_records`` records before the new run: records before a longer
stretch of garbage can be lost if they are fewer than ``lock_records``). The
step bounds also exclude the step a stream shifted by whole timestamp
bytes shows (about 0 or 51 200 us for a record period of 200 us), so a
misaligned run cannot lock even when the fields are constant.

The extension and the lock never take bytes of the record held back for
confirmation (see below) to build a record: when the next record lost its
first 1 or 2 bytes, the held record's last bytes and that record's rest form a
plausible-looking splice. A run may start inside the held record only if its
first record follows it by a sample period, as its second follows its first
(the held record then lost its tail).

**Prefer losing a record to publishing a wrong one.** Two more rules check
each new run against its neighbours:

* when a run starts inside the held record and that record also looks whole
  (its PWM equals its predecessor's, the run's first record's, or one of the
  last commands the host sent, :meth:`RecordDecoder.note_command`), either it
  lost its tail or the next record lost its head and begins with its last
  bytes; which one cannot be told, so both are dropped (``overlaps``). When
  the held record's PWM is none of those, it is the damaged one (its last bytes
  are the next record's timestamp) and only it is dropped;
* a record whose timestamp is not after the newest accepted one (up to
  ``repeat_window`` back: a repeated chunk of the stream) is dropped
  (``repeats``), so no sample is published twice or out of order. A larger
  backward jump is a board restart (below).

Once locked, records are viewed with ``numpy.frombuffer`` over aligned
chunks and checked, and their timestamps unwrapped, by compiled loops
(:mod:`maglev_ros.hardware.v2x_kernels`: one call per burst instead of a
dozen numpy calls); only after a record breaks an invariant does the
decoder search byte by byte (vectorised over all offsets). With ``confirm=True`` (the
default) the newest record is held back until the next record confirms
its end: a record whose tail was cut off (its bytes overlap the next valid
record) is then dropped instead of emitted with foreign bytes. This costs
one record period of latency for the newest record of each burst.

Board time is unwrapped into a monotonic int64 count of microseconds. If
the clock jumps backwards across a resynchronisation (the board was
reset), the jump is counted as a clock restart and the time continues one
sample period (200 us) after the last emitted record.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .packet import PWM_FULL_SCALE
from .v2x_kernels import first_bad_record, unwrap_run

__all__ = [
    'BURST_RECORDS',
    'SAMPLE_PERIOD_US',
    'DecoderStats',
    'PlausibilityBounds',
    'RecordBatch',
    'RecordDecoder',
    'pack_records',
    'record_dtype',
    'record_size',
]

SAMPLE_PERIOD_US = 200  # us between samples (5 kHz)
COMMAND_MEMORY = 4  # commands sent that a record's PWM may still show
BURST_RECORDS = 5  # records per burst (bursts at 1 kHz)
_CLOCK_WRAP = 1 << 32  # us, uint32 timestamp
_HALF_WRAP = 1 << 31  # us; a larger forward step is a backward jump
_CLOCK_MASK = _CLOCK_WRAP - 1
# While searching, bytes up to this many lock runs before the newest possible
# run start are kept, so that a later lock can still extend back over them.
_BACKTRACK_RUNS = 4
# Two consecutive steps of the board clock differ by less than this (it samples
# every 200 us), us: tells a record that follows a truncated one from a splice.
_SPLICE_TOLERANCE_US = 20
# Views of aligned records: timestamps (n,), fields (n, N, 3), PWM (n, 4).
_Run = tuple[np.ndarray, np.ndarray, np.ndarray]


def _check_n_sensors(n_sensors: int) -> int:
    if isinstance(n_sensors, bool) or not isinstance(n_sensors, (int, np.integer)):
        raise TypeError(f'n_sensors must be an int, got {type(n_sensors).__name__}')
    if n_sensors < 1:
        raise ValueError(f'n_sensors must be >= 1, got {n_sensors}')
    return int(n_sensors)


def record_dtype(n_sensors: int) -> np.dtype:
    """Return the packed structured dtype of one record.

    Parameters
    ----------
    n_sensors : int
        Number of sensors in the record (>= 1).

    Returns
    -------
    numpy.dtype
        Fields ``timestamp`` (<u4, us), ``field`` (<f4, shape (n_sensors, 3),
        mT) and ``pwm`` (<i2, shape (4,), counts); itemsize ``4 + 12 n + 8``.
    """
    n = _check_n_sensors(n_sensors)
    return np.dtype([('timestamp', '<u4'), ('field', '<f4', (n, 3)), ('pwm', '<i2', (4,))])


def record_size(n_sensors: int) -> int:
    """Return the size of one record in bytes, ``4 + 12 * n_sensors + 8``.

    Parameters
    ----------
    n_sensors : int
        Sensors per record.
    """
    return 4 + 12 * _check_n_sensors(n_sensors) + 8


def pack_records(timestamp_us: ArrayLike, field_mT: ArrayLike, pwm: ArrayLike) -> bytes:
    """Serialise records exactly as the V2x firmware writes them.

    Parameters
    ----------
    timestamp_us : array_like of int, shape (n,)
        Board clock in us; reduced modulo 2**32.
    field_mT : array_like of float, shape (n, n_sensors, 3)
        Fields in millitesla (written as float32).
    pwm : array_like of int, shape (n, 4)
        Applied PWM in counts (written as int16).

    Returns
    -------
    bytes
        ``n`` records back to back.
    """
    field = np.asarray(field_mT, dtype=np.float32)
    if field.ndim != 3 or field.shape[2] != 3:
        raise ValueError(f'field_mT must have shape (n, n_sensors, 3), got {field.shape}')
    n = field.shape[0]
    stamps = np.asarray(timestamp_us, dtype=np.int64)
    counts = np.asarray(pwm)
    if stamps.shape != (n,):
        raise ValueError(f'timestamp_us must have shape ({n},), got {stamps.shape}')
    if counts.shape != (n, 4):
        raise ValueError(f'pwm must have shape ({n}, 4), got {counts.shape}')
    recs = np.empty(n, dtype=record_dtype(field.shape[1]))
    recs['timestamp'] = (stamps % _CLOCK_WRAP).astype(np.uint32)
    recs['field'] = field
    recs['pwm'] = counts.astype(np.int16)
    return recs.tobytes()


@dataclass(frozen=True)
class PlausibilityBounds:
    """Invariants a record must satisfy (see the module docstring).

    Parameters
    ----------
    max_field_mT : float
        Largest plausible field component magnitude in mT.
    min_step_us, max_step_us : int
        Plausible range of the step between consecutive timestamps in us.
    lock_records : int
        Consecutive plausible records needed to lock onto a boundary (>= 2).
    """

    max_field_mT: float = 1000.0  # noqa: N815 (unit symbol mT)
    min_step_us: int = 100
    max_step_us: int = 10_000
    lock_records: int = 4

    def __post_init__(self) -> None:
        if not self.max_field_mT > 0:
            raise ValueError(f'max_field_mT must be > 0, got {self.max_field_mT}')
        if not 1 <= self.min_step_us <= self.max_step_us < _HALF_WRAP:
            raise ValueError(
                'need 1 <= min_step_us <= max_step_us < 2**31, got '
                f'min_step_us={self.min_step_us}, max_step_us={self.max_step_us}'
            )
        if self.lock_records < 2:
            raise ValueError(f'lock_records must be >= 2, got {self.lock_records}')


class RecordBatch(NamedTuple):
    """Records decoded from one ``feed``.

    Attributes
    ----------
    time_us : ndarray of int64, shape (n,)
        Unwrapped, monotonic board time of each sample in us.
    field_mT : ndarray of float32, shape (n, n_sensors, 3)
        Sensor fields in millitesla, as sent by the board.
    pwm : ndarray of int16, shape (n, 4)
        PWM counts in force at each sample, order x+, x-, y+, y-.
    """

    time_us: NDArray[np.int64]
    field_mT: NDArray[np.float32]  # noqa: N815 (unit symbol mT)
    pwm: NDArray[np.int16]

    def __len__(self) -> int:  # type: ignore[override]
        return int(self.time_us.shape[0])


@dataclass(frozen=True)
class DecoderStats:
    """Counters of a ``RecordDecoder``.

    Attributes
    ----------
    records : int
        Records emitted.
    dropped_bytes : int
        Bytes discarded (garbage, partial or damaged records).
    resyncs : int
        Times the decoder lost a record boundary and searched again.
    wraps : int
        uint32 timestamp wrap-arounds seen.
    clock_restarts : int
        Backward clock jumps (board resets) seen.
    locked : bool
        Whether the decoder currently knows the record boundary.
    overlaps : int
        Pairs of records dropped because a new run started inside a record that
        looked whole (one of the two was damaged; which one cannot be told).
    repeats : int
        Records dropped because they were not after the newest accepted record
        (a repeated chunk of the stream).
    """

    records: int
    dropped_bytes: int
    resyncs: int
    wraps: int
    clock_restarts: int
    locked: bool
    overlaps: int = 0
    repeats: int = 0


class RecordDecoder:
    """Streaming decoder of the V2x record stream.

    Parameters
    ----------
    n_sensors : int
        Sensors per record (not announced by the board; >= 1).
    bounds : PlausibilityBounds, optional
        Invariants used to find boundaries.
    confirm : bool, optional
        Hold the newest record back until the next one confirms its end
        (default True; see the module docstring).
    repeat_window : float, optional
        s: a record up to this much before the newest accepted one is a repeat
        and dropped; further back is a board restart (its clock starts again).
    """

    def __init__(
        self,
        n_sensors: int,
        *,
        bounds: PlausibilityBounds | None = None,
        confirm: bool = True,
        repeat_window: float = 1.0,
    ) -> None:
        if not 0 < repeat_window < 2000:
            raise ValueError(f'repeat_window must be in 0 .. 2000 s, got {repeat_window!r}')
        self.repeat_window_us = round(repeat_window * 1e6)
        self._commands: tuple[tuple[int, ...], ...] = ()
        self.n_sensors = _check_n_sensors(n_sensors)
        self.bounds = bounds if bounds is not None else PlausibilityBounds()
        self.confirm = bool(confirm)
        self._dtype = record_dtype(self.n_sensors)
        self._size = self._dtype.itemsize
        # |B| <= max_field_mT compared on float32 bit patterns (monotonic for |B|).
        self._field_bits = int(np.float32(self.bounds.max_field_mT).view(np.uint32))
        self.reset()

    def reset(self) -> None:
        """Forget the stream: buffered bytes, lock, clock and counters."""
        self._buf = b''
        self._locked = False
        self._head = False  # buf[:size] is an accepted record not yet emitted
        self._prev_ts = 0  # raw timestamp of the last accepted record
        self._last_emit_ts: int | None = None
        self._emitted_run: _Run | None = None  # the newest run queued for emission
        self._overlaps = 0
        self._repeats = 0
        self._last_time_us = 0
        self._records = 0
        self._dropped = 0
        self._resyncs = 0
        self._wraps = 0
        self._restarts = 0

    @property
    def stats(self) -> DecoderStats:
        """Snapshot of the counters."""
        return DecoderStats(
            self._records,
            self._dropped,
            self._resyncs,
            self._wraps,
            self._restarts,
            self._locked,
            self._overlaps,
            self._repeats,
        )

    def note_command(self, pwm: ArrayLike) -> None:
        """Tell the decoder a command the host sent (its PWM counts, x+ x- y+ y-).

        The last ``COMMAND_MEMORY`` commands are PWM values the board may apply:
        a held record whose PWM is one of them is judged intact when a damaged
        record overlaps it. Safe to call from another thread than ``feed``.

        Parameters
        ----------
        pwm : array_like of int, shape (4,)
            The counts sent.
        """
        command = tuple(int(v) for v in np.asarray(pwm).reshape(4))
        self._commands = (command, *self._commands[: COMMAND_MEMORY - 1])

    @property
    def buffered(self) -> int:
        """Bytes received but not yet emitted or dropped."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> RecordBatch:
        """Decode the next chunk of the stream.

        Parameters
        ----------
        data : bytes-like
            Bytes as read from the serial port, any length.

        Returns
        -------
        RecordBatch
            The records completed (and, with ``confirm``, confirmed) by
            this chunk, in order.
        """
        self._buf = self._buf + bytes(data) if self._buf else bytes(data)
        out: list[_Run] = []
        while True:
            if self._locked:
                if not self._run_locked(out):
                    break
            elif not self._search(out):
                break
        return self._emit(out)

    def flush(self) -> RecordBatch:
        """Emit the held-back record without waiting for confirmation.

        Returns
        -------
        RecordBatch
            The held-back record, or an empty batch.
        """
        out: list[_Run] = []
        if self._head:
            self._push(out, self._views(self._buf, 1))
            self._buf = self._buf[self._size :]
            self._head = False
        return self._emit(out)

    # -- internals --------------------------------------------------------------

    def _views(self, buf: bytes, n: int) -> _Run:
        """Timestamp (n,), field (n, N, 3) and PWM (n, 4) views of n aligned records."""
        records = np.frombuffer(buf, self._dtype, count=n)
        return records['timestamp'], records['field'], records['pwm']

    def _run_locked(self, out: list[_Run]) -> bool:
        """Decode aligned records; return True if the boundary was lost."""
        size = self._size
        buf = self._buf
        n = len(buf) // size
        start = 1 if self._head else 0
        if n <= start:
            if self._head and not self.confirm:
                self._push(out, self._views(buf, 1))
                self._buf = buf[size:]
                self._head = False
            return False
        bounds = self.bounds
        ts, field, pwm = self._views(buf, n)
        bad = first_bad_record(
            np.frombuffer(buf, '<u4', count=n * size // 4).reshape(n, size // 4),
            start,
            self._prev_ts,
            3 * self.n_sensors,
            bounds.min_step_us,
            bounds.max_step_us,
            self._field_bits,
            PWM_FULL_SCALE,
        )
        ok = bad == n
        last = bad - 1  # index of the last accepted record, -1 if none
        failed = not ok
        emit_end = last if self.confirm else last + 1
        if emit_end > 0:
            self._push(out, (ts[:emit_end], field[:emit_end], pwm[:emit_end]))
        if last >= 0:
            self._prev_ts = int(ts[last])
        self._head = self.confirm and last >= 0
        self._buf = buf[max(emit_end, 0) * size :]
        if failed:
            self._locked = False
            self._resyncs += 1
        return failed

    def _find_lock(self, buf: bytes, first: int) -> tuple[int | None, int]:
        """Earliest offset >= first starting ``lock_records`` plausible records.

        Returns the offset, extended backwards, or None and the number of
        leading bytes that can be discarded.
        """
        size = self._size
        k = self.bounds.lock_records
        length = len(buf)
        m = length - k * size + 1  # candidate offsets 0 .. m-1
        if m <= first:
            return None, 0
        # Unaligned views of every type at every byte offset (stride 1).
        span = length - 3
        f32 = np.ndarray((span,), '<f4', buf, 0, (1,))
        u32 = np.ndarray((span,), '<u4', buf, 0, (1,))
        i16 = np.ndarray((length - 1,), '<i2', buf, 0, (1,))
        ok_f = np.abs(f32) <= self.bounds.max_field_mT
        ok_p = (i16 >= -PWM_FULL_SCALE) & (i16 <= PWM_FULL_SCALE)
        n_rec = length - size + 1  # offsets where a whole record fits
        rec_ok = np.ones(n_rec, dtype=bool)
        for j in range(3 * self.n_sensors):
            rec_ok &= ok_f[4 + 4 * j : 4 + 4 * j + n_rec]
        pwm_at = 4 + 12 * self.n_sensors
        for j in range(4):
            rec_ok &= ok_p[pwm_at + 2 * j : pwm_at + 2 * j + n_rec]
        n_step = length - 2 * size + 1
        step = u32[size : size + n_step] - u32[:n_step]
        step_ok = (step >= self.bounds.min_step_us) & (step <= self.bounds.max_step_us)
        run = rec_ok[:m].copy()
        for r in range(1, k):
            run &= rec_ok[r * size : r * size + m]
            run &= step_ok[(r - 1) * size : (r - 1) * size + m]
        if self._head:
            # A run starting inside the held-back record means that record lost its
            # tail; the run's first record then follows it by one sample period, as
            # the second record follows the first. A run that does not is led by a
            # record spliced from the held-back record's last bytes and the rest of a
            # record that lost its first bytes (its timestamp off by up to 2**(8 L)
            # us for L lost bytes): not a boundary.
            inside = min(size, m)
            into = (u32[first:inside] - np.uint32(self._prev_ts)).astype(np.int64)
            onward = step[first:inside].astype(np.int64)
            run[first:inside] &= (
                (into >= self.bounds.min_step_us)
                & (into <= self.bounds.max_step_us)
                & (np.abs(onward - into) <= _SPLICE_TOLERANCE_US)
            )
        hits = np.flatnonzero(run[first:])
        if not hits.size:
            # Offsets below m start no run; keep the last _BACKTRACK_RUNS *
            # lock_records records' worth of them for a later backward extension.
            return None, max(0, m - _BACKTRACK_RUNS * k * size)
        offset = first + int(hits[0])
        # Extend backwards: the latest plausible record that ends at or before
        # the run and steps correctly into it belongs to the stream too (it
        # sat just before a damaged record, or directly before the run).
        # With a held-back record at buf[:size], the extension stays behind it: that
        # record passed every check, and a candidate overlapping it would be made of
        # its bytes (its timestamp, then the head of a record that lost its first
        # bytes), stealing it and stamping the damaged record with its time.
        low, high = self.bounds.min_step_us, self.bounds.max_step_us
        back_first = size if self._head else first
        while offset - size >= back_first:
            span = slice(back_first, offset - size + 1)
            steps = u32[offset] - u32[span]
            back = np.flatnonzero(rec_ok[span] & (steps >= low) & (steps <= high))
            if not back.size:
                break
            offset = back_first + int(back[-1])
        return offset, m

    def _search(self, out: list[_Run]) -> bool:
        """Look for a boundary; return True once locked or after dropping records."""
        size = self._size
        buf = self._buf
        first = 1 if self._head else 0
        offset, ruled_out = self._find_lock(buf, first)
        if offset is None:
            # Drop the leading bytes that can no longer start a lock, but keep
            # a held-back record that a later lock might overlap.
            if self._head:
                if ruled_out < size:
                    return False
                self._push(out, self._views(buf, 1))
                self._head = False
                self._dropped += ruled_out - size
            else:
                self._dropped += ruled_out
            self._buf = buf[ruled_out:]
            return False
        if self._head:
            if offset >= size:  # the held-back record ends before the new boundary
                self._push(out, self._views(buf, 1))
                self._dropped += offset - size
            elif self._head_consistent(buf, offset):
                # The run starts inside the held-back record, and both look whole: the
                # held record's PWM is one the board applied, and the run's first record
                # follows it by a sample period. Either the held record lost its tail or
                # the next one lost its head, and its first bytes are the held record's
                # last ones; which one cannot be told, so both are dropped.
                self._dropped += offset + size
                self._overlaps += 1
                offset += size
            else:  # the held record lost its tail: its last bytes start the next record
                self._dropped += offset
        else:
            self._dropped += offset
        self._head = False
        # A record that is not after the newest one accepted repeats it or an earlier
        # one (a repeated chunk of the stream): drop it, never publish a sample twice.
        skipped = 0
        ref = self._emitted_ts
        while ref is not None and offset + size <= len(buf):
            back = (ref - int(np.frombuffer(buf, '<u4', count=1, offset=offset)[0])) & _CLOCK_MASK
            if back >= self.repeat_window_us:
                break
            offset += size
            skipped += 1
        self._dropped += skipped * size
        self._repeats += skipped
        self._buf = buf[offset:]
        if skipped:  # search again from there (the rest of the run is checked anew)
            return True
        self._head = True  # the first record of the run is accepted
        self._prev_ts = int(np.frombuffer(self._buf, '<u4', count=1)[0])
        self._locked = True
        return True

    def _head_consistent(self, buf: bytes, offset: int) -> bool:
        """Whether the held record's PWM is one the board applied (a neighbour's or a command).

        ``buf[:size]`` is the held record, ``buf[offset:offset + size]`` the first
        record of a new run that overlaps it.
        """
        size = self._size
        held = tuple(np.frombuffer(buf, '<i2', count=4, offset=size - 8).tolist())
        after = tuple(np.frombuffer(buf, '<i2', count=4, offset=offset + size - 8).tolist())
        return held == after or held == self._emitted_pwm or held in self._commands

    def _push(self, out: list[_Run], run: _Run) -> None:
        """Queue a run of records for emission; remember it (its newest record)."""
        out.append(run)
        self._emitted_run = run

    @property
    def _emitted_ts(self) -> int | None:
        """Raw stamp of the newest record queued for emission, None before any."""
        run = self._emitted_run
        return None if run is None else int(run[0][-1])

    @property
    def _emitted_pwm(self) -> tuple[int, ...] | None:
        """PWM of the newest record queued for emission, None before any."""
        run = self._emitted_run
        return None if run is None else tuple(run[2][-1].tolist())

    def _emit(self, out: list[_Run]) -> RecordBatch:
        """Unwrap the timestamps of emitted record runs and join them."""
        if not out:
            return RecordBatch(
                np.empty(0, np.int64),
                np.empty((0, self.n_sensors, 3), np.float32),
                np.empty((0, 4), np.int16),
            )
        times = []
        for ts, _, _ in out:
            last_raw = -1 if self._last_emit_ts is None else self._last_emit_ts
            # a contiguous, writable copy: one compiled signature for every run (a
            # one-record view counts as contiguous to numpy, a longer one not, and a new
            # signature would compile mid-stream)
            time_us, restarts, wraps = unwrap_run(
                ts.copy(), last_raw, self._last_time_us, SAMPLE_PERIOD_US
            )
            self._restarts += restarts
            self._wraps += wraps
            self._last_emit_ts = int(ts[-1])
            self._last_time_us = int(time_us[-1])
            self._records += ts.shape[0]
            times.append(time_us)
        if len(out) == 1:
            return RecordBatch(times[0], out[0][1], out[0][2])
        return RecordBatch(
            np.concatenate(times),
            np.concatenate([run[1] for run in out]),
            np.concatenate([run[2] for run in out]),
        )
