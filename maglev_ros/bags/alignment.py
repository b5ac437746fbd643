"""Put the samples of several topics on one time base of uniform sample spacing.

Stamps
    A message's time is its ``header.stamp`` if the message has a header (and
    the stamps are not all zero), else the bag's log (receive) time. Commands
    are ``sensor_msgs/JointState`` stamped with the sample they answer, so they
    align with it exactly; bags recorded before carry them as header-less
    ``std_msgs/Float64MultiArray``, placed by the time the recorder logged them.

The rule
    The first output topic defines the time base.  ``Ts`` is given or estimated
    from its stamps (the median stamp difference, refined over the whole record
    so that no drift builds up).  If its stamps are uniform sample to sample
    (every stamp difference within ``tolerance * Ts`` of ``Ts``, default 5 %,
    hence no gaps), the time base is that topic's own samples: sample ``k`` at
    its own stamp ``t_k``.  Otherwise it is the grid ``t_k = t_0 + k Ts``, with
    ``t_0`` the topic's first stamp.  A topic whose stamps coincide one to one
    with the time base's ``t_k`` within ``tolerance * Ts`` (its period within
    the tolerance of ``Ts``, every message within the tolerance of its nearest
    ``t_k``, no two at the same one) is taken sample by sample, unchanged
    (*exact* match: in a lockstep run all topics share the
    simulator's clock, exactly on the grid; a board driver stamps the field and
    currents of one record alike, uniform but slowly drifting against any fixed
    grid; either way the data set is exactly the published sequence).
    Otherwise outputs are resampled by linear interpolation at the ``t_k`` and
    inputs by zero-order hold: the input at ``t_k`` is the last input stamped at
    or before ``t_k`` (within the tolerance), which is the value the plant was
    holding.  Samples where some topic has no data yet (or any more: an input
    counts for one of its own periods after its last message, to the end if it
    has only one, except an input taken exactly, which ends with its last
    message) are trimmed from the start and the end.

Gaps
    Each topic is checked against its own sample period (estimated as for
    ``Ts``): a stamp difference above 1.5 periods is a gap of
    ``round(difference / period) - 1`` dropped samples.  Gaps are refused by
    default with an error naming the topic, the time and the number of missing
    samples; with ``allow_gaps=True`` outputs are filled by linear interpolation
    and inputs by zero-order hold, and every fill is reported.  Repeated stamps
    are dropped (the first message is kept) and counted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .errors import BagError

__all__ = [
    'GAP_FACTOR',
    'Alignment',
    'Gap',
    'Source',
    'SourceReport',
    'align',
    'estimate_period',
    'find_gaps',
]

#: A stamp difference above GAP_FACTOR sample periods is a gap.
GAP_FACTOR = 1.5
#: Default tolerance of an exact stamp match, as a fraction of Ts.
TOLERANCE = 0.05


@dataclass(frozen=True)
class Source:
    """The samples of one topic.

    Parameters
    ----------
    topic : str
        Topic name.
    stamps : ndarray of int64, shape (n,)
        Sample times in ns (header stamps or log times).
    values : ndarray, shape (n, k)
        The topic's ``k`` extracted fields.
    role : {'output', 'input'}
        Outputs define the time base and are interpolated linearly; inputs are
        held (zero-order hold).
    clock : {'header', 'log'}
        Where the stamps come from.
    """

    topic: str
    stamps: np.ndarray
    values: np.ndarray
    role: str
    clock: str = 'header'


@dataclass(frozen=True)
class Gap:
    """Dropped samples of one topic.

    Parameters
    ----------
    topic : str
        Topic name.
    time : float
        Time of the last sample before the gap, s after the start of the time base.
    missing : int
        Number of missing samples.
    filled : str
        ``'linear'`` or ``'zoh'`` if it was filled, ``''`` if not.
    """

    topic: str
    time: float
    missing: int
    filled: str = ''

    def describe(self) -> str:
        """Return a one-line description."""
        what = f'{self.missing} missing sample{"s" if self.missing != 1 else ""}'
        fill = f', filled by {self.filled}' if self.filled else ''
        return f'{self.topic}: {what} after t = {self.time:.6f} s{fill}'


@dataclass(frozen=True)
class SourceReport:
    """How one topic was put on the time base.

    Parameters
    ----------
    topic : str
        Topic name.
    role : str
        ``'output'`` or ``'input'``.
    clock : str
        ``'header'`` or ``'log'``.
    samples : int
        Messages read (after dropping repeated stamps).
    period : float
        The topic's own sample period, s (``inf`` for a single message).
    method : str
        ``'exact'``, ``'linear'`` or ``'zoh'``.
    duplicates : int
        Messages dropped for repeating a stamp.
    gaps : tuple of Gap
        The topic's gaps.
    """

    topic: str
    role: str
    clock: str
    samples: int
    period: float
    method: str
    duplicates: int
    gaps: tuple[Gap, ...]


@dataclass(frozen=True)
class Alignment:
    """Samples of several topics on one uniform time base.

    Parameters
    ----------
    t0_ns : int
        Time of the first sample, ns.
    Ts : float
        Sample time, s.
    values : tuple of ndarray, each shape (N, k)
        Per source (in the order given), its fields on the time base.
    reports : tuple of SourceReport
        Per source, how it was aligned.
    trimmed : tuple of int
        Samples of the base trimmed at the start and at the end.
    base : {'grid', 'stamps'}
        The time base: the uniform grid ``t_0 + k Ts``, or the first output's own
        (uniform) stamps.
    """

    t0_ns: int
    Ts: float
    values: tuple[np.ndarray, ...]
    reports: tuple[SourceReport, ...]
    trimmed: tuple[int, int]
    base: str = 'grid'

    @property
    def N(self) -> int:  # noqa: N802 - sample count, as IdData
        """Number of samples."""
        return int(self.values[0].shape[0]) if self.values else 0

    @property
    def gaps(self) -> tuple[Gap, ...]:
        """All gaps, in topic order."""
        return tuple(g for r in self.reports for g in r.gaps)


def estimate_period(stamps: np.ndarray) -> float:
    """Estimate the sample period of increasing stamps, s.

    The median difference, refined as the whole span over the number of periods
    it holds (so a 3 kHz clock rounded to ns does not drift).

    Parameters
    ----------
    stamps : ndarray of int64, shape (n,)
        Increasing stamps in ns, ``n >= 2``.

    Returns
    -------
    float
        Period in s (``inf`` if ``n < 2``).
    """
    stamps = np.asarray(stamps, dtype=np.int64)
    if stamps.size < 2:
        return float('inf')
    diffs = np.diff(stamps).astype(float)
    median = float(np.median(diffs))
    periods = float(np.sum(np.maximum(np.rint(diffs / median), 1.0)))
    return float(stamps[-1] - stamps[0]) / periods * 1e-9


def find_gaps(topic: str, stamps: np.ndarray, period: float, t0_ns: int) -> tuple[Gap, ...]:
    """Find gaps: stamp differences above ``GAP_FACTOR`` periods.

    Parameters
    ----------
    topic : str
        Topic name for the report.
    stamps : ndarray of int64, shape (n,)
        Increasing stamps, ns.
    period : float
        Sample period, s.
    t0_ns : int
        Origin of the reported times, ns.

    Returns
    -------
    tuple of Gap
        One per gap, in time order.
    """
    if stamps.size < 2 or not np.isfinite(period):
        return ()
    diffs = np.diff(stamps).astype(float) * 1e-9
    where = np.flatnonzero(diffs > GAP_FACTOR * period)
    missing = np.rint(diffs[where] / period).astype(int) - 1
    return tuple(
        Gap(topic, (int(stamps[i]) - t0_ns) * 1e-9, max(int(m), 1))
        for i, m in zip(where, missing, strict=True)
    )


def _clean(source: Source) -> tuple[np.ndarray, np.ndarray, int]:
    stamps = np.asarray(source.stamps, dtype=np.int64)
    values = np.asarray(source.values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    if stamps.ndim != 1 or values.shape[0] != stamps.size:
        raise BagError(f'{source.topic}: {stamps.size} stamps but {values.shape[0]} samples')
    if stamps.size == 0:
        raise BagError(f'topic {source.topic!r} has no messages')
    if np.any(np.diff(stamps) < 0):
        order = np.argsort(stamps, kind='stable')
        stamps, values = stamps[order], values[order]
    keep = np.ones(stamps.size, dtype=bool)
    keep[1:] = np.diff(stamps) > 0
    duplicates = int(stamps.size - np.count_nonzero(keep))
    if duplicates:
        stamps, values = stamps[keep], values[keep]
    return stamps, values, duplicates


def _first_gap_error(gaps: Sequence[Gap]) -> BagError:
    first = gaps[0]
    more = (
        f' ({len(gaps)} gaps, {sum(g.missing for g in gaps)} samples in all)'
        if len(gaps) > 1
        else ''
    )
    return BagError(
        f'gap in topic {first.topic!r}: {first.missing} missing sample'
        f'{"s" if first.missing != 1 else ""} after t = {first.time:.6f} s{more}; '
        f'pass allow_gaps=True (--allow-gaps) to interpolate outputs and hold '
        f'inputs across gaps'
    )


def align(
    sources: Sequence[Source],
    Ts: float | None = None,
    allow_gaps: bool = False,
    tolerance: float = TOLERANCE,
) -> Alignment:
    """Align topics on the time base of the first output (see the module docstring).

    Parameters
    ----------
    sources : sequence of Source
        At least one output; the first output defines the time base.
    Ts : float, optional
        Sample time in s (default: estimated from the first output's stamps).
    allow_gaps : bool
        Fill gaps (outputs linearly, inputs by zero-order hold) instead of refusing.
    tolerance : float
        Exact-match tolerance as a fraction of ``Ts``, in (0, 0.5).

    Returns
    -------
    Alignment
        Values on the time base and a report per source.

    Raises
    ------
    BagError
        No output, too few samples, gaps (unless allowed), no time overlap.
    """
    if not 0.0 < tolerance < 0.5:
        raise BagError(f'tolerance must be a fraction of Ts in (0, 0.5), got {tolerance!r}')
    for s in sources:
        if s.role not in ('output', 'input'):
            raise BagError(f"{s.topic}: role must be 'output' or 'input', got {s.role!r}")
    outputs = [s for s in sources if s.role == 'output']
    if not outputs:
        raise BagError('choose at least one output channel: outputs define the time base')
    cleaned = [_clean(s) for s in sources]
    base_index = sources.index(outputs[0])
    base_stamps = cleaned[base_index][0]
    if base_stamps.size < 2:
        raise BagError(
            f'topic {outputs[0].topic!r} has {base_stamps.size} sample: '
            f'at least 2 are needed for a time base'
        )
    if Ts is None:
        Ts = estimate_period(base_stamps)
    Ts = float(Ts)
    if not np.isfinite(Ts) or Ts <= 0:
        raise BagError(f'Ts must be a positive sample time in s, got {Ts!r}')
    ts_ns, tol_ns = Ts * 1e9, tolerance * Ts * 1e9
    t0 = int(base_stamps[0])
    own = bool(np.all(np.abs(np.diff(base_stamps) - ts_ns) <= tol_ns))
    if own:  # uniform sample to sample: the base is the topic's own samples
        grid = base_stamps
    else:
        count = int(np.floor((int(base_stamps[-1]) - t0 + tol_ns) / ts_ns)) + 1
        grid = t0 + np.rint(np.arange(count) * ts_ns).astype(np.int64)
    count = int(grid.size)

    gaps_all: list[Gap] = []
    first_ok, last_ok = 0, count - 1
    results: list[tuple[np.ndarray, str, float, tuple[Gap, ...]]] = []
    for source, (stamps, values, _) in zip(sources, cleaned, strict=True):
        period = estimate_period(stamps)
        gaps = find_gaps(source.topic, stamps, period, t0)
        gaps_all.extend(gaps)
        if source.role == 'input':
            out, method, first, last = _hold(stamps, values, grid, ts_ns, tol_ns, period)
        else:
            out, method, first, last = _match_or_interpolate(
                stamps, values, grid, ts_ns, tol_ns, period
            )
        first_ok, last_ok = max(first_ok, first), min(last_ok, last)
        results.append((out, method, period, gaps))
    if gaps_all and not allow_gaps:
        raise _first_gap_error(gaps_all)
    if last_ok < first_ok:
        spans = ', '.join(
            f'{s.topic} {(int(c[0][0]) - t0) * 1e-9:.3f}..{(int(c[0][-1]) - t0) * 1e-9:.3f} s'
            for s, c in zip(sources, cleaned, strict=True)
        )
        clocks = {s.clock for s in sources}
        hint = (
            '; header stamps and log times come from different clocks: record with '
            'the clock that stamps the messages (use_sim_time in simulation)'
            if len(clocks) > 1
            else ''
        )
        raise BagError(f'the topics do not overlap in time: {spans}{hint}')
    window = slice(first_ok, last_ok + 1)
    reports = []
    for source, (_, _, dups), (_, method, period, gaps) in zip(
        sources, cleaned, results, strict=True
    ):
        fill = 'zoh' if source.role == 'input' else 'linear'
        filled = tuple(Gap(g.topic, g.time, g.missing, fill) for g in gaps)
        reports.append(
            SourceReport(
                source.topic,
                source.role,
                source.clock,
                int(source.stamps.size) - dups,
                period,
                method,
                dups,
                filled,
            )
        )
    values = tuple(np.ascontiguousarray(r[0][window]) for r in results)
    return Alignment(
        int(grid[first_ok]),
        Ts,
        values,
        tuple(reports),
        (first_ok, count - 1 - last_ok),
        'stamps' if own else 'grid',
    )


def _nearest(grid: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """Index of the time base sample nearest to each stamp (both increasing, int64 ns)."""
    if grid.size == 1:
        return np.zeros(stamps.size, dtype=np.int64)
    right = np.clip(np.searchsorted(grid, stamps), 1, grid.size - 1)
    left = right - 1
    return np.where(stamps - grid[left] <= grid[right] - stamps, left, right)


def _match_or_interpolate(
    stamps: np.ndarray,
    values: np.ndarray,
    grid: np.ndarray,
    ts_ns: float,
    tol_ns: float,
    period: float,
) -> tuple[np.ndarray, str, int, int]:
    """Output: exact sample match if every message is on the time base, else linear.

    ``grid`` (int64 ns, increasing) is the time base, uniform or the first
    output's own stamps. Every message within the base's span must lie within
    ``tol_ns`` of its nearest base sample, one message per base sample. A topic
    at another rate whose messages happen to lie on base samples (1 kHz on a
    5 kHz base) is reported as ``'linear'``: most of its samples are
    interpolated.
    """
    first = int(np.searchsorted(grid, stamps[0] - tol_ns, side='left'))
    last = int(np.searchsorted(grid, stamps[-1] + tol_ns, side='right')) - 1
    inside = (stamps >= grid[0] - 0.5 * ts_ns) & (stamps < grid[-1] + 0.5 * ts_ns)
    k_in = _nearest(grid, stamps[inside])
    on_grid = bool(
        np.all(np.abs(stamps[inside] - grid[k_in]) <= tol_ns) and np.all(np.diff(k_in) > 0)
    )
    t = (stamps - stamps[0]).astype(float)
    tg = (grid - stamps[0]).astype(float)
    out = np.empty((grid.size, values.shape[1]))
    for col in range(values.shape[1]):
        out[:, col] = np.interp(tg, t, values[:, col])
    same_rate = abs(period * 1e9 - ts_ns) <= tol_ns
    if not (on_grid and same_rate):
        return out, 'linear', first, last
    # every message sits on its base sample: take it unchanged; only dropped samples
    # (gaps) keep the interpolated value
    out[k_in] = values[inside]
    return out, 'exact', first, last


def _hold(
    stamps: np.ndarray,
    values: np.ndarray,
    grid: np.ndarray,
    ts_ns: float,
    tol_ns: float,
    period: float,
) -> tuple[np.ndarray, str, int, int]:
    """Input: zero-order hold of the last sample at or before each base time.

    Held for one of its own periods after its last message (a topic that stopped
    publishing is not extended), to the end if it has a single message (a set-point
    sent once). An input at the base's rate with a message within ``tol_ns`` of
    every base sample it covers is taken exactly and covers up to its last
    message only: a sample after it would be held, not published.
    """
    j = np.searchsorted(stamps, grid + tol_ns, side='right') - 1
    first = int(np.searchsorted(j, 0, side='left'))
    if np.isfinite(period):
        last = int(np.searchsorted(grid, stamps[-1] + period * 1e9 + tol_ns, side='right')) - 1
    else:
        last = grid.size - 1
    jj = np.clip(j, 0, stamps.size - 1)
    out = values[jj]
    exact = np.abs(stamps[jj] - grid) <= tol_ns
    if np.all(exact[first : last + 1]):
        return out, 'exact', first, last
    last_message = int(np.searchsorted(grid, stamps[-1] + tol_ns, side='right')) - 1
    same_rate = abs(period * 1e9 - ts_ns) <= tol_ns
    if same_rate and first <= last_message and np.all(exact[first : last_message + 1]):
        return out, 'exact', first, last_message
    return out, 'zoh', first, last
