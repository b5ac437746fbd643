"""Map the board's sample clock to host time (offset and drift, slewed, never stepping).

Every read from the port gives one observation: the board time ``b`` of the
newest record (us) and the host time ``h`` of the read (ns). With the board
clock running at rate ``1 + d`` against the host clock,

    h = 1000 b + offset + d * 1000 b + latency,   latency >= 0,

so the lower envelope of ``h - 1000 b`` is a line whose intercept is the
offset and whose slope is the drift. ``BoardClock`` keeps the minimum of
``h - 1000 b`` per bucket of board time (default 1 s) and, once three
buckets are complete, fits the lower envelope of the minima of the last
complete buckets (default 30): the line below all of them that is highest at
their mean board time (the edge of their lower convex hull over the mean,
the linear-programming estimate of offset and skew). Minima above the
envelope do not move it: a bucket whose reads were all late (the host
stalled, then read a backlog) is ignored, where a least-squares line would
tilt by up to a percent and jump by the stall. A hull edge can still run to
such a minimum at the end of a short window; so a minimum higher than
another by more than ``max_drift`` (default 0.5 %) of their distance plus
1 ms is left out. The current bucket's minimum
joins the fit once it lies below the line of the complete ones (its first
reads are typical, not fast ones). Board times are mapped through that line
(the *target*). Before three buckets are complete the offset is the minimum
seen so far and the drift 0. The hull is found in integer arithmetic and the
line passes through a minimum exactly: epoch-sized offsets (1.7e18 ns) keep
their ns.

Slewing
    Until the first stamp is mapped, the mapping is the target itself: the
    first observation sets the offset directly. After that, a change of the
    target (a new minimum of the read latency lowers the line, a new fit
    turns it) never steps the stamps: the applied offset follows the target's
    slope and moves towards the target by at most ``slew`` (default 2 %) of
    the board time elapsed, i.e. at most 4 us per 200 us sample. Consecutive
    stamps are therefore ``1000 (b_i - b_{i-1}) (1 + drift)`` ns apart within
    ``slew`` of that spacing (plus 3 ns of rounding), and a correction of
    ``c`` takes ``c / slew`` of board time (0.8 ms in 40 ms). The remaining
    correction is kept in ps and decays linearly with board time, so mapping
    a batch at once or in pieces gives the same stamps.
Jumps
    A correction larger than ``max_slew`` (default 50 ms: the board was reset
    or replugged without a reconnect, which slewing would take seconds to
    absorb) is applied at once: forwards the stamps jump, backwards they are
    held back (below).
Monotonic
    Stamps are forced to increase strictly (by at least 1 ns), also across
    calls: only a backward jump beyond ``max_slew`` or board times that do not
    increase can make this hold stamps back.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['BoardClock']

_SCALAR_MAX = 16  # samples; up to here a Python loop beats numpy's per-call overhead
_STALL_MARGIN_NS = 1_000_000  # spread of the bucket minima beyond drift before a stall


class BoardClock:
    """Board time (us) to host time (ns) mapping with drift estimation and slewing.

    Parameters
    ----------
    bucket : float, optional
        Board-time span in s over which one minimum is kept (> 0).
    buckets : int, optional
        Number of recent complete buckets whose minima the line is fitted to (>= 3).
    slew : float, optional
        Largest correction of the applied offset per unit of board time
        (dimensionless, in [1e-6, 0.1]; default 0.02: 4 us per 200 us sample).
        Resolved to whole ppm.
    max_slew : float, optional
        Corrections larger than this (s, > 0; default 0.05) are applied at once
        instead of slewed.
    max_drift : float, optional
        Largest plausible clock rate error (dimensionless, in (0, 0.1]; default
        0.005, a ceramic resonator): a bucket minimum higher than another one by
        more than this drift over their distance plus 1 ms is a stall, left out
        of the fit.
    """

    def __init__(
        self,
        bucket: float = 1.0,
        buckets: int = 30,
        slew: float = 0.02,
        max_slew: float = 0.05,
        max_drift: float = 0.005,
    ) -> None:
        if not bucket > 0:
            raise ValueError(f'bucket must be > 0 s, got {bucket!r}')
        if buckets < 3:
            raise ValueError(f'buckets must be >= 3, got {buckets!r}')
        if not 1e-6 <= slew <= 0.1:
            raise ValueError(f'slew must be a fraction in [1e-6, 0.1], got {slew!r}')
        if not max_slew > 0:
            raise ValueError(f'max_slew must be > 0 s, got {max_slew!r}')
        if not 0 < max_drift <= 0.1:
            raise ValueError(f'max_drift must be in (0, 0.1], got {max_drift!r}')
        self._bucket_us = int(round(bucket * 1e6))
        self._buckets = buckets
        # (board us, h - 1000 b) of the last `buckets` complete buckets and the current one
        self._minima: deque[tuple[int, int]] = deque(maxlen=buckets + 1)
        self._current_bucket: int | None = None
        self._slope = 0.0  # ns per us of board time, i.e. drift * 1000
        self._ref_us = 0
        self._intercept_ns = 0
        self._slew = float(slew)
        self._slew_ppm = int(round(slew * 1e6))  # ps of correction per us of board time
        self._max_slew = float(max_slew)
        self._max_slew_ps = int(round(max_slew * 1e12))
        self._max_drift = float(max_drift)
        self._mapped_us: int | None = None  # latest board time mapped
        self._error_ps = 0  # target minus applied offset at _mapped_us, ps
        self._last_stamp_ns: int | None = None
        self._ramp = np.arange(1, 65, dtype=np.int64)  # 1, 2, ... (cached)
        self.observations = 0

    def reset(self) -> None:
        """Forget all observations (new board or new power-up)."""
        self.__init__(
            self._bucket_us * 1e-6,
            self._buckets,  # type: ignore[misc]
            self._slew,
            self._max_slew,
            self._max_drift,
        )

    @property
    def drift(self) -> float:
        """Estimated board clock rate error (dimensionless, e.g. 5e-5 = 50 ppm fast host)."""
        return self._slope / 1000.0

    @property
    def slew(self) -> float:
        """Largest offset correction per unit of board time (dimensionless)."""
        return self._slew

    @property
    def pending_ns(self) -> int:
        """Correction still to be slewed at the latest mapped board time, ns.

        Target minus applied offset (positive: the stamps run early and are
        being moved later); 0 once the mapping has reached the fitted line.
        """
        return self._error_ps // 1000 if self._error_ps >= 0 else -(-self._error_ps // 1000)

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
        if self._mapped_us is None:
            self._fit()  # nothing mapped yet: the mapping is the new line itself
            return
        before = self._target_ns(self._mapped_us)
        self._fit()
        error = self._error_ps + 1000 * (self._target_ns(self._mapped_us) - before)
        self._error_ps = 0 if abs(error) > self._max_slew_ps else error

    def _fit(self) -> None:
        """Fit the target line to the complete buckets, and to the current one if lower.

        The current bucket's minimum is still falling (its first read is a
        typical one, not a fast one); it counts once the bucket is complete, or
        as soon as it lies below the line of the complete buckets.
        """
        *complete, current = self._minima
        if len(complete) < 3:
            self._ref_us = current[0]
            self._slope = 0.0
            self._intercept_ns = min(m[1] for m in self._minima)
            return
        self._line(complete)
        if current[1] < self._target_ns(current[0]):
            self._line(self._minima)

    def _line(self, minima) -> None:
        """Fit the lower envelope: the line below every minimum, highest at their mean.

        The line under all points ``(x_i, y_i)`` that minimises ``sum(y_i -
        line(x_i))`` is the lower convex hull's edge over the mean ``x`` (the
        linear-programming estimate of clock offset and skew). Unlike least
        squares it ignores minima above the envelope: a bucket whose reads
        were all late (the host stalled and caught up) does not tilt the line.
        Integer arithmetic for the hull: no rounding of epoch-sized offsets.
        """
        # a minimum above another by more than max_drift allows (plus a margin for
        # the latency's spread) is a stall: its reads all came late
        rate = 1000.0 * self._max_drift  # ns per us
        minima = [
            (x, y)
            for x, y in minima
            if all(y - y2 <= rate * abs(x - x2) + _STALL_MARGIN_NS for x2, y2 in minima)
        ]
        hull: list[tuple[int, int]] = []
        for x, y in sorted(minima):
            while len(hull) >= 2:
                (x0, y0), (x1, y1) = hull[-2], hull[-1]
                if (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0) > 0:
                    break  # a left turn: (x1, y1) stays on the lower hull
                hull.pop()
            hull.append((x, y))
        if len(hull) == 1:  # all minima at one board time
            self._ref_us, self._intercept_ns, self._slope = hull[0][0], hull[0][1], 0.0
            return
        n, total = len(minima), sum(m[0] for m in minima)
        # the edge [x_k, x_k+1] with x_k <= mean x < x_k+1 (the last one if at the end)
        k = 0
        while k + 2 < len(hull) and hull[k + 1][0] * n <= total:
            k += 1
        (x0, y0), (x1, y1) = hull[k], hull[k + 1]
        self._ref_us, self._intercept_ns = x0, y0
        self._slope = (y1 - y0) / (x1 - x0)

    def _target_ns(self, board_us: int) -> int:
        """Offset of the fitted line at one board time (host ns minus 1000 board us)."""
        return self._intercept_ns + int(round(self._slope * float(board_us - self._ref_us)))

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
        if self._mapped_us is None:
            self._mapped_us = int(board[0])
        if board.size <= _SCALAR_MAX:
            return self._to_host_scalar(board)
        rel = (board - self._ref_us).astype(np.float64)
        stamps = 1000 * board + self._intercept_ns + np.rint(self._slope * rel).astype(np.int64)
        # the remaining correction decays linearly with board time after _mapped_us
        error = self._error_ps
        sign, size = (1 if error >= 0 else -1), abs(error)
        if size:
            cap = size // self._slew_ppm + 1  # us after which the correction is done
            elapsed = np.clip(board - self._mapped_us, 0, cap)
            remaining = np.maximum(size - elapsed * self._slew_ppm, 0)
            stamps -= sign * (remaining // 1000)
            size = int(remaining[-1])
        # strictly increasing, also across calls: s_i >= s_{i-1} + 1
        if self._ramp.size < board.size:
            self._ramp = np.arange(1, 2 * board.size + 1, dtype=np.int64)
        ramp = self._ramp[: board.size]
        floor = -(1 << 62) if self._last_stamp_ns is None else self._last_stamp_ns
        stamps = np.maximum.accumulate(np.maximum(stamps - ramp, floor)) + ramp
        self._last_stamp_ns = int(stamps[-1])
        if int(board[-1]) > self._mapped_us:
            self._mapped_us = int(board[-1])
            self._error_ps = sign * size
        return stamps

    def _to_host_scalar(self, board: NDArray[np.int64]) -> NDArray[np.int64]:
        """``to_host`` for a few samples: the same arithmetic without numpy's per-call cost.

        Python's ``round`` and ``numpy.rint`` both round half to even, the
        products are the same float64 operations and the correction is integer
        arithmetic, so both paths agree exactly.
        """
        ref, slope, intercept = self._ref_us, self._slope, self._intercept_ns
        last = -(1 << 62) if self._last_stamp_ns is None else self._last_stamp_ns
        mapped, rate = self._mapped_us, self._slew_ppm
        assert mapped is not None
        sign, size = (1 if self._error_ps >= 0 else -1), abs(self._error_ps)
        remaining = size
        out = []
        for b in board.tolist():
            elapsed = b - mapped if b > mapped else 0
            remaining = size - elapsed * rate
            if remaining < 0:
                remaining = 0
            stamp = (
                1000 * b
                + intercept
                + int(round(slope * float(b - ref)))
                - sign * (remaining // 1000)
            )
            last = stamp if stamp > last else last + 1
            out.append(last)
        self._last_stamp_ns = last
        if out and int(board[-1]) > mapped:
            self._mapped_us = int(board[-1])
            self._error_ps = sign * remaining
        return np.array(out, dtype=np.int64)
