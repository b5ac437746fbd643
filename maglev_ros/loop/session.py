"""The lab session on any plant: settle, excite, record exactly N samples, stop.

Written once for every plant the loop runs (a lockstep or paced simulation,
a board) and for open or closed loop (a loop whose controller only passes
the excitation on). :func:`run_session` runs a :class:`~maglev_ros.loop.ControlLoop`:

1. **settle**: the first ``settle_samples + 1`` samples (ordinals 0 ..
   ``settle_samples``; the plant's own sample numbers do not matter); the
   position error over the last ``settle_window`` of them gives the settled
   RMS (the true state of a simulation, the estimate on a board);
2. **excite**: the excitation's first row is added to the command answering
   ordinal ``settle_samples``, the next rows to the following samples (the
   loop looks its rows up by the plant's sample number: the session sets
   them once it knows the first one);
3. **record**: the recording observers get exactly the ``samples`` samples
   after the settling (ordinals ``settle_samples + 1`` on), each as a
   :class:`WindowSample`: the loop's sample, the command that drives the
   coils from it and that command's excitation (the first one carries the
   command in force when the window opens: a paced loop answers only the
   newest sample of each read);
4. **stop**: after the last recorded sample, when the plant stops (a lost
   magnet, a failed link) or when ``stop()`` turns true (a signal). The
   plant is closed in every case: a board's coils are left at zero.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .control_loop import ControlLoop, LoopSample

__all__ = ['SessionPlan', 'SessionResult', 'WindowSample', 'run_session']

REPORT_EVERY = 250  # samples between progress reports


class WindowSample(NamedTuple):
    """A recorded sample, as the recording observers get it.

    Attributes
    ----------
    sample : LoopSample
        The loop's sample.
    command : ndarray, shape (n_s,) or None
        The command that drives the coils from this sample on, A (what was
        written after it; the first recorded sample: the command in force);
        None: the loop wrote nothing after it (the previous one holds).
    excitation : ndarray, shape (n_s,) or None
        The excitation part of ``command``, A (through the command delay).
    """

    sample: LoopSample
    command: np.ndarray | None
    excitation: np.ndarray | None


@dataclass(frozen=True)
class SessionPlan:
    """What a session runs.

    Attributes
    ----------
    samples : int
        Samples to record, >= 1.
    settle_samples : int
        Ordinal of the last settling sample (the recording starts at the
        next), >= 1; or 0: no settling, the recording starts with the first
        sample (an open-loop recording).
    settle_window : int
        Samples of the settling check's RMS (the last ones before the window).
    set_point : ndarray, shape (3,)
        Position the error is taken from, m.
    settled_rms : float
        Settled when the RMS is below this on every axis, m.
    position : {'state', 'estimate'}
        The position checked: the true state (simulations) or the estimate.
    excitation : ndarray, shape (M, n_s), optional
        Currents added to the commands from ordinal ``settle_samples`` on, A
        (row i at ordinal ``settle_samples + i``; nothing after row M - 1).
    """

    samples: int
    settle_samples: int
    settle_window: int = 500
    set_point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    settled_rms: float = 1e-4
    position: str = 'state'
    excitation: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name, least in (('samples', 1), ('settle_samples', 0), ('settle_window', 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f'{name} must be an integer >= {least}, got {value!r}')
        if self.position not in ('state', 'estimate'):
            raise ValueError(f"position must be 'state' or 'estimate', got {self.position!r}")

    @property
    def total(self) -> int:
        """Samples the loop handles: the settling's and the recording's."""
        return self.settle_samples + (1 if self.settle_samples else 0) + self.samples


@dataclass(frozen=True)
class SessionResult:
    """What a session did.

    Attributes
    ----------
    samples : int
        Samples recorded (``plan.samples`` unless stopped early).
    settle_rms : ndarray, shape (3,)
        RMS of the position error over the settling window, m (NaN: none).
    settled : bool
        Below ``plan.settled_rms`` on every axis.
    settle_s : float
        Plant time from the first sample to the last settling one, s.
    recorded_s : float
        Plant time of the recording, from the last settling sample to the
        last recorded one, s.
    wall_s : float
        Wall time of the recording, s.
    run_wall_s : float
        Wall time of the whole session, s.
    positions : ndarray, shape (n, 3)
        The checked position (not its error) over the recording, m (an
        estimate may be missing where the readings were).
    commands : int
        Commands written over the recording.
    stopped : bool
        ``stop()`` ended the session.
    crashed : bool
        The plant stopped (a lost magnet, a failed link).
    reason : str
        Why it stopped.
    controller : dict
        The controller's final ``level``, ``message``, ``saturated`` and
        ``timeouts``.
    dropped : dict of str to int
        Samples each named recording observer dropped (those with a
        ``dropped`` count: an :class:`~maglev_ros.loop.ObserverThread`).
    """

    samples: int
    settle_rms: np.ndarray
    settled: bool
    settle_s: float
    recorded_s: float
    wall_s: float
    run_wall_s: float
    positions: np.ndarray
    commands: int
    stopped: bool
    crashed: bool
    reason: str
    controller: dict
    dropped: dict


class _Tracker:
    """The session's own observer: ordinals, excitation start, settling, the window."""

    def __init__(self, loop: ControlLoop, plan: SessionPlan, recorders: list) -> None:
        self.loop = loop
        self.plan = plan
        self.recorders = recorders
        self.n = 0  # samples seen
        self.recorded = 0
        self.commands = 0
        n_s = loop.plant.n_inputs
        self._zero = np.zeros(n_s)
        # the excitation of each command waiting in the loop's delay line, oldest first
        self._delayed = deque(self._zero for _ in range(loop.command_delay))
        self._in_force: tuple[np.ndarray, np.ndarray] | None = None
        lo = plan.settle_samples - plan.settle_window + 1
        # no settling (0): no ordinal is in the range
        self._settle_range = (max(lo, 0), plan.settle_samples if plan.settle_samples else -1)
        self._settling: list[np.ndarray] = []
        self.positions: list[np.ndarray] = []
        self.times = [np.nan, np.nan, np.nan]  # first sample, last settling, last recorded
        self.opened_at: float | None = None
        self.closed_at: float | None = None

    def __call__(self, s: LoopSample) -> None:
        j = self.n
        self.n += 1
        plan = self.plan
        if j == 0:
            self.times[0] = s.t
            ex = plan.excitation
            if ex is not None:  # rows by the plant's sample number, from the settle ordinal
                pad = np.zeros((s.index + plan.settle_samples, ex.shape[1]))
                self.loop.excitation = np.concatenate([pad, ex])
        applied_ex = None
        if s.applied is not None:
            ex = self._zero if s.excitation is None else s.excitation
            if self._delayed:
                self._delayed.append(ex)
                ex = self._delayed.popleft()
            applied_ex = ex
        lo, hi = self._settle_range
        if j <= hi:
            if j >= lo:
                p = self._position(s)
                if p is not None:
                    self._settling.append(p)
            if j == hi:
                self.times[1] = s.t
            if s.applied is not None:
                self._in_force = (s.applied, applied_ex)
            return
        if self.recorded >= plan.samples:
            return
        if self.recorded == 0:
            self.opened_at = time.monotonic()
        command, excitation = s.applied, applied_ex
        if command is None and self.recorded == 0 and self._in_force is not None:
            command, excitation = self._in_force
        if s.applied is not None:
            self.commands += 1
        p = self._position(s)
        if p is not None:
            self.positions.append(p)
        item = WindowSample(s, command, excitation)
        for recorder in self.recorders:
            recorder(item)
        self.recorded += 1
        self.times[2] = s.t
        if self.recorded == plan.samples:
            self.closed_at = time.monotonic()

    def _position(self, s: LoopSample) -> np.ndarray | None:
        x = s.state if self.plan.position == 'state' else s.estimate
        return None if x is None else x[:3]

    def settle_rms(self) -> np.ndarray:
        if not self._settling:
            return np.full(3, np.nan)
        error = np.array(self._settling) - self.plan.set_point
        return np.sqrt(np.mean(np.square(error), axis=0))


def run_session(
    loop: ControlLoop,
    plan: SessionPlan,
    observers: Mapping[str, Callable[[WindowSample], None]] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> SessionResult:
    """Run a lab session (see the module docstring) on ``loop``; close its plant.

    Parameters
    ----------
    loop : ControlLoop
        The loop, on its plant, reset (warmed up if it runs in real time).
    plan : SessionPlan
        What to run.
    observers : mapping of str to callable, optional
        The recording observers by name, called with each recorded
        :class:`WindowSample` in order (in the loop's thread: put a slow one
        behind an :class:`~maglev_ros.loop.ObserverThread`; its drops are
        reported). The caller closes them.
    progress : callable, optional
        ``progress(stage, done, total)``: stage ``settling`` or ``recording``,
        samples; called every few hundred samples.
    stop : callable, optional
        Polled between the loop's reads; True ends the session.

    Returns
    -------
    SessionResult
    """
    named = dict(observers or {})
    tracker = _Tracker(loop, plan, list(named.values()))
    loop.observers.add(tracker)
    report = progress or (lambda stage, done, total: None)
    asked = stop or (lambda: False)
    started = time.monotonic()
    stopped = False
    settle_total = plan.total - plan.samples
    reported = 0
    try:
        while tracker.n < plan.total and not loop.stopped:
            # a read's samples beyond the session's last are dropped, none before
            loop.step(limit=plan.total - tracker.n)
            if tracker.n - reported >= REPORT_EVERY or tracker.n >= plan.total:
                reported = tracker.n
                if tracker.n < settle_total:
                    report('settling', tracker.n, settle_total)
                else:
                    report('settling', settle_total, settle_total)
                    report('recording', tracker.recorded, plan.samples)
            if asked():
                stopped = tracker.n < plan.total
                break
    finally:
        loop.observers.remove(tracker)
        loop.plant.close()  # a board's coils at zero, also on an error
    status = loop.controller.status()
    rms = tracker.settle_rms()
    end = tracker.closed_at or time.monotonic()
    t0, t_settled, t_last = tracker.times
    return SessionResult(
        samples=tracker.recorded,
        settle_rms=rms,
        settled=bool(np.all(rms < plan.settled_rms)),
        settle_s=float(t_settled - t0) if np.isfinite(t_settled) else float('nan'),
        recorded_s=float(t_last - (t_settled if plan.settle_samples else t0))
        if tracker.recorded
        else 0.0,
        wall_s=end - tracker.opened_at if tracker.opened_at is not None else 0.0,
        run_wall_s=time.monotonic() - started,
        positions=np.array(tracker.positions).reshape(-1, 3),
        commands=tracker.commands,
        stopped=stopped,
        crashed=bool(loop.stopped),
        reason=loop.reason,
        controller={
            'level': status.level,
            'message': status.message,
            'saturated': int(status.saturated),
            'timeouts': int(status.timeouts),
        },
        dropped={k: int(getattr(o, 'dropped', 0)) for k, o in named.items()},
    )
