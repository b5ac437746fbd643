"""Map the board's sample clock to host time (offset and drift, no backward jumps).

Every read from the port gives one observation: the board time ``b`` of the
newest record (us) and the host time ``h`` of the read (ns). With the board
clock running at rate ``1 + d`` against the host clock,

    h = 1000 b + offset + d * 1000 b + latency,   latency >= 0,

so the lower envelope of ``h - 1000 b`` is a line whose intercept is the
offset and whose slope is the drift. ``BoardClock`` keeps the minimum of
``h - 1000 b`` per bucket of board time (default 1 s), fits a line through
the minima of the last buckets (default 30) once there are three, and maps
board times through that line. Before that the offset is the minimum seen
so far and the drift 0. Mapped stamps are forced to increase strictly (by
at least 1 ns): when a new minimum lowers the line, stamps are held back
until the line catches up instead of jumping backwards.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['BoardClock']

_SCALAR_MAX = 16  # samples; up to here a Python loop beats numpy's per-call overhead


class BoardClock:
    """Board time (us) to host time (ns) mapping with drift estimation.

    Parameters
    ----------
    bucket : float, optional
        Board-time span in s over which one minimum is kept (> 0).
    buckets : int, optional
        Number of recent bucket minima the line is fitted to (>= 3).
    """

    def __init__(self, bucket: float = 1.0, buckets: int = 30) -> None:
        if not bucket > 0:
            raise ValueError(f'bucket must be > 0 s, got {bucket!r}')
        if buckets < 3:
            raise ValueError(f'buckets must be >= 3, got {buckets!r}')
        self._bucket_us = int(round(bucket * 1e6))
        self._minima: deque[tuple[int, int]] = deque(maxlen=buckets)  # (board us, h - 1000 b)
        self._current_bucket: int | None = None
        self._slope = 0.0  # ns per us of board time, i.e. drift * 1000
        self._ref_us = 0
        self._intercept_ns = 0
        self._last_stamp_ns: int | None = None
        self._ramp = np.arange(1, 65, dtype=np.int64)  # 1, 2, ... (cached)
        self.observations = 0

    def reset(self) -> None:
        """Forget all observations (new board or new power-up)."""
        self.__init__(self._bucket_us * 1e-6, self._minima.maxlen)  # type: ignore[misc]

    @property
    def drift(self) -> float:
        """Estimated board clock rate error (dimensionless, e.g. 5e-5 = 50 ppm fast host)."""
        return self._slope / 1000.0

    def observe(self, board_us: int, host_ns: int) -> None:
        """Add one observation.

        Parameters
        ----------
        board_us : int
            Board time of the newest record of a read, in us (unwrapped).
        host_ns : int
            Host time of that read, in ns.
        """
        board_us = int(board_us)
        delta = int(host_ns) - 1000 * board_us
        bucket = board_us // self._bucket_us
        self.observations += 1
        if bucket != self._current_bucket or not self._minima:
            self._minima.append((board_us, delta))
            self._current_bucket = bucket
        elif delta < self._minima[-1][1]:
            self._minima[-1] = (board_us, delta)
        else:
            return  # the minima did not change: neither does the line
        self._fit()

    def _fit(self) -> None:
        x = np.array([m[0] for m in self._minima], dtype=np.float64)
        y = np.array([m[1] for m in self._minima], dtype=np.float64)
        self._ref_us = int(x[-1])
        if len(x) >= 3:
            xc = x - x[-1]
            slope, intercept = np.polyfit(xc, y, 1)
            self._slope = float(slope)
            self._intercept_ns = int(round(intercept))
        else:
            self._slope = 0.0
            self._intercept_ns = int(y.min())

    def to_host(self, board_us: ArrayLike) -> NDArray[np.int64]:
        """Map board times to strictly increasing host times.

        Parameters
        ----------
        board_us : array_like of int, shape (n,)
            Increasing board times in us (unwrapped).

        Returns
        -------
        ndarray of int64, shape (n,)
            Host times in ns, each later than every stamp returned before.

        Raises
        ------
        ValueError
            If no observation was made yet.
        """
        if not self._minima:
            raise ValueError('BoardClock needs an observation before mapping board_us')
        board = np.asarray(board_us, dtype=np.int64)
        if board.size == 0:
            return np.empty(0, np.int64)
        if board.size <= _SCALAR_MAX:
            return self._to_host_scalar(board)
        rel = (board - self._ref_us).astype(np.float64)
        stamps = 1000 * board + self._intercept_ns + np.rint(self._slope * rel).astype(np.int64)
        # strictly increasing, also across calls: s_i >= s_{i-1} + 1
        if self._ramp.size < board.size:
            self._ramp = np.arange(1, 2 * board.size + 1, dtype=np.int64)
        ramp = self._ramp[: board.size]
        floor = -(1 << 62) if self._last_stamp_ns is None else self._last_stamp_ns
        stamps = np.maximum.accumulate(np.maximum(stamps - ramp, floor)) + ramp
        self._last_stamp_ns = int(stamps[-1])
        return stamps

    def _to_host_scalar(self, board: NDArray[np.int64]) -> NDArray[np.int64]:
        """``to_host`` for a few samples: the same arithmetic without numpy's per-call cost.

        Python's ``round`` and ``numpy.rint`` both round half to even, and the
        products are the same float64 operations, so both paths agree exactly.
        """
        ref, slope, intercept = self._ref_us, self._slope, self._intercept_ns
        last = -(1 << 62) if self._last_stamp_ns is None else self._last_stamp_ns
        out = []
        for b in board.tolist():
            stamp = 1000 * b + intercept + int(round(slope * float(b - ref)))
            last = stamp if stamp > last else last + 1
            out.append(last)
        self._last_stamp_ns = last
        return np.array(out, dtype=np.int64)
