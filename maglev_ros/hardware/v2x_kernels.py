"""Compiled inner loops of the V2x decoder: record invariants, timestamp unwrapping.

``RecordDecoder`` handles one 5-record burst per millisecond at 5 kHz. A
handful of numpy calls per burst cost tens of microseconds of per-call
overhead, far more than the work itself; these numba kernels do the same
work in one call of about a microsecond each, for a burst or a backlog of
any length.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ['first_bad_record', 'unwrap_run']

_CLOCK_MASK = 0xFFFF_FFFF
_MAGNITUDE = 0x7FFF_FFFF  # float32 bits without the sign
_HALF_WRAP = 1 << 31  # us; a larger forward step is a backward jump


@njit(cache=True)
def first_bad_record(
    rows: np.ndarray,
    start: int,
    prev_ts: int,
    n_field: int,
    min_step_us: int,
    max_step_us: int,
    field_bits: int,
    pwm_full_scale: int,
) -> int:
    """Index of the first record that breaks an invariant, or the record count.

    Parameters
    ----------
    rows : ndarray of uint32, shape (n, w)
        Aligned records as little-endian 32-bit words: timestamp (us), then
        ``n_field`` float32 field components, then the four int16 PWM
        values packed in the last two words.
    start : int
        Records before ``start`` are already accepted and not checked (0 or 1).
    prev_ts : int
        Raw timestamp (us) of the record before ``rows[0]``; the step into
        ``rows[0]`` is checked when ``start`` is 0.
    n_field : int
        Field components per record (3 per sensor).
    min_step_us, max_step_us : int
        Plausible timestamp step range in us (uint32 steps: wrap-safe).
    field_bits : int
        float32 bit pattern of the largest plausible ``|B|`` (mT); a larger
        magnitude, NaN or infinity is bad.
    pwm_full_scale : int
        Largest plausible ``|PWM|`` in counts.

    Returns
    -------
    int
        The index of the first bad record at or after ``start``, ``n`` if
        every record is plausible.
    """
    n, width = rows.shape
    prev = np.int64(prev_ts) if start == 0 else np.int64(rows[start - 1, 0])
    for i in range(start, n):
        ts = np.int64(rows[i, 0])
        step = (ts - prev) & _CLOCK_MASK
        if step < min_step_us or step > max_step_us:
            return i
        prev = ts
        for j in range(1, 1 + n_field):
            if np.int64(rows[i, j]) & _MAGNITUDE > field_bits:
                return i
        for j in range(width - 2, width):
            word = np.int64(rows[i, j])
            for half in (word & 0xFFFF, word >> 16):
                value = half - 0x10000 if half >= 0x8000 else half
                if value < -pwm_full_scale or value > pwm_full_scale:
                    return i
    return n


@njit(cache=True)
def unwrap_run(
    ts: np.ndarray, last_raw: int, last_time_us: int, period_us: int
) -> tuple[np.ndarray, int, int]:
    """Unwrap the raw uint32 timestamps of a run of validated records.

    Parameters
    ----------
    ts : ndarray of uint32, shape (n,), n >= 1
        Raw timestamps (us) of consecutive validated records (each step in
        ``1 .. 2**31``).
    last_raw : int
        Raw timestamp of the last record emitted before, or -1 for none.
    last_time_us : int
        Its unwrapped time in us.
    period_us : int
        Sample period in us: the step assumed when the clock jumped back
        (the board restarted).

    Returns
    -------
    time_us : ndarray of int64, shape (n,)
        Monotonic board time in us (the first record of the stream keeps
        its raw timestamp).
    restarts : int
        1 if the clock jumped back into this run, else 0.
    wraps : int
        uint32 wrap-arounds crossed, into and inside the run.
    """
    n = ts.shape[0]
    first = np.int64(ts[0])
    restarts = 0
    wraps = 0
    if last_raw < 0:
        t0 = first
    else:
        step0 = (first - last_raw) & _CLOCK_MASK
        if step0 >= _HALF_WRAP:  # backwards: the board's clock restarted
            restarts = 1
            step0 = period_us
        elif first < last_raw:
            wraps += 1
        t0 = last_time_us + step0
    time_us = np.empty(n, np.int64)
    time_us[0] = t0
    for i in range(1, n):
        time_us[i] = time_us[i - 1] + ((np.int64(ts[i]) - np.int64(ts[i - 1])) & _CLOCK_MASK)
    wraps += ((first + time_us[n - 1] - t0) >> 32) - (first >> 32)
    return time_us, restarts, wraps
