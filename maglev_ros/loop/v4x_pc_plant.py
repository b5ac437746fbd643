"""A board running the V4x PC-control firmware as the control loop's plant.

:class:`V4xPcPlant` is a :class:`~maglev_ros.loop.Plant` on a
:class:`~maglev_ros.hardware.v4x_pc_link.V4xPcLink` (COBS request/response,
``docs/boards.md``). The firmware sends nothing by itself: the host asks.

**One round trip per sample.** The plant runs on a fixed schedule of
``sample_rate`` samples per second (default 1000 Hz, above the 800 Hz of the
lab's own host). At each period's start :meth:`read` sends, in one write,
the command that :meth:`write` left (``03``), then ``01`` (sensors) and
``02`` (currents) (:meth:`V4xPcLink.command_and_sample`), and waits for the
three replies. The board answers them in one loop pass: the field is its
latest filtered sample, taken before the command; the currents are its ADC
reading with the command applied. So the command computed from sample k
drives the coils from sample k+1 (one period of command delay, which the LQR
design takes as a state), and the currents of sample k are the ones held
until sample k+1: the discrete model the estimator and the identification
assume, with no fraction of a period to model.

**Timing.** The replies carry no sample counter, and a host's stamps jitter
with its wake-ups; the plant stamps each sample with its *scheduled* time:
the host's system clock (``time.time_ns``, as the driver stamps) at the first
sample's replies, plus the schedule's time since then (``k / sample_rate``
while the schedule holds). So stamps are uniform and a late period shows as
the gap it is. The request goes out when the host wakes, after the
scheduled time by :attr:`wake_delays` (the board's field is its latest 200 us
sample then). The loop sees ``sample_rate`` as its rate. :meth:`open` measures the board's
round-trip rate (``round_trip_rate``: one over the median round trip with
nothing else to do) and refuses a sample rate it cannot carry with 25 % to
spare. A host that wakes a whole period or more late has missed those
periods: the block holds one row per missed period (readings NaN, so the
estimator predicts across them with the currents held; ``late`` counts
them) before the sample, which keeps the estimator's time the board's.
More than 50 missed periods restart the schedule (a gap).
:attr:`rate_reached` reports the rate the samples came at.

**Commands.** Coil currents (A, x+ x- y+ y-) pass a
:class:`~maglev_ros.hardware.command_guard.CommandGuard` with ``pairs=True``:
the firmware applies pair differences only (x+ gets ``p_x``, x- ``-p_x``),
so the nearest antisymmetric command is sent, clamped at ``current_limit``
and scaled to PWM counts by the ``scaling`` (coil resistance and supply).
:meth:`applied` gives the currents a command becomes.

**Zero current.** The firmware has no watchdog. The link resets the coils
(``04``) when it opens, after a reply timeout or a bad reply; the plant
closes the link (``04`` again, best effort) when it stops on an error and in
:meth:`close`; a link error ends the run (the block is ``crashed`` with the
reason).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..hardware.command_guard import CommandGuard, pair_differences
from ..hardware.scaling import CurrentScaling
from ..hardware.serial_link import LinkError
from ..hardware.v4x_pc_link import V4xPcLink
from .plant import SampleBlock

__all__ = ['DEFAULT_RATE', 'RATE_MARGIN', 'V4xPcPlant']

#: Samples per second by default, Hz (the lab's host PD runs at 800 Hz).
DEFAULT_RATE = 1000.0
#: A sample rate needs this factor more round trips per second than one per period.
RATE_MARGIN = 1.25
_RATE_PROBES = 200  # round trips timed by open()
_MAX_MISSED = 50  # missed periods filled with predict-only rows; beyond, the schedule restarts
_REOPEN_S = 0.05  # s between attempts to reopen a lost link for its reset


class V4xPcPlant:
    """The V4x PC-control board as a :class:`~maglev_ros.loop.Plant` (module docstring).

    Parameters
    ----------
    link : V4xPcLink
        The board's link (opened by :meth:`open` if it is not).
    scaling : CurrentScaling
        Coil current to PWM counts (255 counts at full duty).
    current_limit : float
        Largest commanded |current|, A (at most the scaling's full scale).
    sample_rate : float, optional
        Samples per second, Hz (default :data:`DEFAULT_RATE`).
    clock : callable, optional
        Monotonic time, s (default :func:`time.monotonic`).
    sleep : callable, optional
        Waits a number of seconds (default :func:`time.sleep`).
    reset_wait : float, optional
        s :meth:`close` keeps trying to reset the coils after the link was
        lost (default 2).

    Attributes
    ----------
    round_trip_rate : float
        Round trips per second measured by :meth:`open`: one over the median
        of 200 round trips (NaN before), Hz.
    round_trip_p99 : float
        Their 99th percentile, s.
    late : int
        Periods the host missed (woke a whole period or more late).
    periods : list of float
        Time between successive samples, s (for the rate reached).
    coils_reset : bool
        A ``04`` was acknowledged after the run stopped or the plant closed.
    wake_delays : list of float
        Per sample, how late after its scheduled time the request went out, s.
    """

    lockstep = False
    n_inputs = 4

    def __init__(
        self,
        link: V4xPcLink,
        scaling: CurrentScaling,
        current_limit: float,
        sample_rate: float = DEFAULT_RATE,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        reset_wait: float = 2.0,
    ) -> None:
        if not 0 < sample_rate < float('inf'):
            raise ValueError(f'sample_rate must be a positive number, got {sample_rate!r}')
        self.link = link
        self.guard = CommandGuard(scaling, current_limit, 1.0, enabled=True, pairs=True)
        self.sample_rate = float(sample_rate)
        self.period = 1.0 / self.sample_rate
        self.clock = clock
        self.sleep = sleep
        self.reset_wait = float(reset_wait)
        self.coils_reset = False
        self._resets_seen = 0
        self.round_trip_rate = float('nan')
        self.round_trip_p99 = float('nan')
        self.late = 0
        self.periods: list[float] = []
        self.stopped = ''
        self._k = 0
        self._due: float | None = None
        self._t0 = 0.0
        self._last_t: float | None = None
        self._wall0_ns = 0
        self.wake_delays: list[float] = []
        self._command = (0, 0)  # pair differences sent with the next read
        self._held_currents = np.zeros(4)  # the currents of the last sample, A

    # -- handle ---------------------------------------------------------------------------

    def open(self) -> V4xPcPlant:
        """Open the link (ping, ``04``), measure the round-trip rate, check the sample rate.

        Returns
        -------
        V4xPcPlant
            ``self``.

        Raises
        ------
        LinkError
            If the board does not answer (the message names the port and firmware).
        ValueError
            If the board's round trips are too slow for ``sample_rate``; the
            link is closed (coils reset) first.
        """
        if not self.link.is_open:
            self.link.open()
        self._resets_seen = self.link.counts.resets - 1  # open's own 04 counts
        try:
            times = [self.clock()]
            for _ in range(_RATE_PROBES):
                self.link.command_and_sample(0, 0)
                times.append(self.clock())
            trips = np.diff(times)
            self.round_trip_rate = 1.0 / max(float(np.median(trips)), 1e-9)
            self.round_trip_p99 = float(np.percentile(trips, 99))
        except LinkError:
            self.link.close()
            raise
        need = RATE_MARGIN * self.sample_rate
        if self.round_trip_rate < need:
            self.link.close()
            raise ValueError(
                f'{self.link.port}: the board answers {self.round_trip_rate:.0f} round trips '
                f'per second; {self.sample_rate:g} Hz needs {need:.0f} ({RATE_MARGIN:g}x '
                'to spare): lower the sample rate'
            )
        return self

    def close(self) -> None:
        """Reset the coils (``04``) and close the link (idempotent).

        After a link error whose ``04`` did not get through (the cable was
        pulled: the board, on its own supply, keeps its PWM), the plant keeps
        trying to reopen the port and reset the coils for ``reset_wait`` s
        (a cable put back meanwhile gets its ``04``); :attr:`coils_reset`
        says whether a reset was acknowledged.
        """
        if self.link.is_open:
            self.link.close()
            self.coils_reset = self.coils_reset or self._reset_acknowledged()
        deadline = self.clock() + self.reset_wait
        while self.stopped and not self.coils_reset and self.clock() < deadline:
            try:
                self.link.open()  # ping, then 04
            except LinkError:
                self.sleep(_REOPEN_S)
                continue
            self.link.close()
            self.coils_reset = True

    def __enter__(self) -> V4xPcPlant:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- Plant ----------------------------------------------------------------------------

    def read(self) -> SampleBlock:
        """Wait for the next period; send the pending command, read sensors and currents.

        Returns
        -------
        SampleBlock
            The sample (field T, currents A), after one row per period the host
            missed (woke a whole period or more late): readings NaN (the estimator
            predicts across them), currents the ones held; or an empty
            ``crashed`` block after a link error (the coils were reset and the
            link closed).
        """
        if self.stopped:
            return _stopped(self.stopped)
        now = self.clock()
        missed = 0
        if self._due is None:
            self._due = now
        elif self._due > now:
            self.sleep(self._due - now)
        else:
            missed = int((now - self._due) / self.period)
            if missed > _MAX_MISSED:  # far behind: the schedule restarts here (a gap)
                self.late += 1
                self._due, missed = now, 0
            elif missed:
                self.late += missed
                self._due += missed * self.period
        try:
            sample = self.link.command_and_sample(*self._command)
            t = self.clock()
        except LinkError as err:
            return self._fail(f'link error: {err}')
        due = self._due
        if self._last_t is None:
            self._t0 = due
            self._wall0_ns = sample.stamp_ns
        else:
            self.periods.append(t - self._last_t)
        self._last_t = t
        self._resets_seen = self.link.counts.resets  # a command went out: 04s from here on
        self.wake_delays.append(t - due)
        self._due += self.period
        n = missed + 1
        k = self._k
        self._k += n
        since = due - self._t0 - self.period * np.arange(missed, -1, -1)
        readings = np.full((n, 3), np.nan)
        readings[-1] = sample.field_mT * 1e-3
        currents = np.empty((n, 4))
        currents[:-1] = self._held_currents
        currents[-1] = sample.currents_A
        self._held_currents = currents[-1].copy()
        return SampleBlock(
            index=np.arange(k, k + n),
            times=since,
            stamps_ns=self._wall0_ns + np.rint(since * 1e9).astype(np.int64),
            readings=readings,
            currents=currents,
            valid=np.ones(n, dtype=bool),
        )

    def write(self, command: np.ndarray, stamp_ns: int) -> None:
        """Keep the command for the next :meth:`read` (the start of the next period).

        Parameters
        ----------
        command : ndarray, shape (4,)
            Coil currents, A, order x+, x-, y+, y-.
        stamp_ns : int
            Stamp of the sample the command answers, ns.
        """
        if self.stopped:
            return
        decision = self.guard.command(command, stamp_ns)
        if decision.counts is None:
            self._fail(f'command refused: {decision.warning}')
            return
        self._command = pair_differences(decision.counts)

    def applied(self, command: np.ndarray) -> np.ndarray:
        """Return the currents the board applies for ``command`` (pairs, clamp, PWM), A.

        Parameters
        ----------
        command : ndarray, shape (4,)
            Coil currents, A.
        """
        c = np.asarray(command, dtype=float)
        u = np.clip(
            np.array([c[0] - c[1], c[2] - c[3]]) / 2,
            -self.guard.current_limit,
            self.guard.current_limit,
        )
        counts = self.guard.scaling.to_counts(np.array([u[0], -u[0], u[1], -u[1]]))
        return self.guard.scaling.to_current(counts)

    @property
    def rate_reached(self) -> float:
        """Samples per second over the run so far, Hz (NaN before two samples)."""
        if not self.periods:
            return float('nan')
        return len(self.periods) / float(np.sum(self.periods))

    def _fail(self, reason: str) -> SampleBlock:
        self.stopped = reason
        self.link.close()  # 04, best effort: no watchdog on the board
        self.coils_reset = self._reset_acknowledged()
        return _stopped(reason)

    def _reset_acknowledged(self) -> bool:
        """Whether a ``04`` was acknowledged after the last command sent."""
        return self.link.counts.resets > self._resets_seen


def _stopped(reason: str) -> SampleBlock:
    return SampleBlock(
        index=np.empty(0, dtype=np.int64),
        times=np.empty(0),
        stamps_ns=np.empty(0, dtype=np.int64),
        readings=np.empty((0, 3)),
        currents=np.empty((0, 4)),
        valid=np.empty(0, dtype=bool),
        crashed=True,
        reason=reason,
    )
