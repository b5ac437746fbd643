"""A simulation session: the simulator's pacing, commands and run state, ROS-free.

:class:`SimulationSession` wraps a :class:`~maglev_ros.physics.Simulator` and
decides when samples are stepped and with which command. It never publishes:
each call returns the samples to publish as a :class:`SampleBatch` (or None),
and the caller (the simulator node) serialises and sends them. Time is passed
in (``now``, s of a monotonic clock), so the session runs the same in a node,
a test or a script. It is not thread-safe: the caller serialises its calls
and the publishing of their batches (one lock), so batches go out in order.

Timing modes
------------
``realtime``
    :meth:`~SimulationSession.pace`, called in a loop, steps the samples due
    at wall time ``now`` in bursts of ``pace_period`` s (at least one sample)
    with the latest command, and says how long to wait before the next call.
    A command applies from the next burst on. A command is *late* when at
    least one sample was stepped with the held command since the previous
    one; such samples are counted as *held*. More than ``MAX_BACKLOG_S``
    behind, the backlog is dropped (an *overrun*) and pacing restarts at
    ``now``.
``lockstep``
    The lockstep contract, which the estimator and controller nodes follow
    too:

    1. Nothing is published before :meth:`~SimulationSession.start` (the
       caller starts once its peers are there); it returns sample 0.
    2. After publishing sample k, exactly one command is awaited for it.
       Commands are taken in order; early ones queue, and each one steps
       one sample (:meth:`~SimulationSession.command` returns the stepped
       samples; a burst of one, or more when commands had queued).
    3. After ``command_timeout`` s without a command
       (:meth:`~SimulationSession.check_timeout`, called periodically) the
       last command is held for one sample and a *timeout* is counted.

    Deterministic given the simulator's seed.

In both modes, pausing stops stepping (queued lockstep commands wait),
:meth:`~SimulationSession.pause_after` pauses by itself once a given sample
was stepped (lockstep: an exact number of samples, e.g. a recording), a
crash stops the integration until :meth:`~SimulationSession.reset`, and a
reset starts a new run at sample 0 stamped one sample period after the last
published sample: simulated time increases across runs.

Stamps: sample i of a run is stamped ``run_start_ns + round(i * 1e9 /
sample_rate)`` ns of simulated time.

Averaged samples (``average`` N > 1, real time): the simulator steps at its
sample rate (the sensing rate) and the session returns one sample per N
steps, the mean of their readings and currents, stamped (with its true
state) at the group's last step, sample ``m`` of the slower rate at step
``m N`` (:class:`~maglev_ros.physics.sample_average.SampleAverager`; the
run's initial sample alone is sample 0). A burst of ``pace_period`` = N steps
ends a group, so a command applies from a group's start. The counters count
steps, :attr:`SimulationSession.command_lag` steps too.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .sample_average import SampleAverager
from .sample_batch import SampleBatch
from .simulation import Simulator

__all__ = [
    'COUNTERS',
    'MAX_BACKLOG_S',
    'MODES',
    'PAUSED_POLL_S',
    'CommandError',
    'SampleBatch',
    'SimulationSession',
    'Tick',
    'timeout_line',
]

MODES = ('realtime', 'lockstep')
MAX_BACKLOG_S = 0.1  # s of wall time real time may catch up at most
PAUSED_POLL_S = 0.01  # s between pace() calls while paused or crashed
COUNTERS = (
    'samples',
    'commands',
    'commands_rejected',
    'late_commands',
    'held_samples',
    'timeouts',
    'overruns',
    'crashes',
    'resets',
)
_ZERO = np.zeros(4)


class CommandError(ValueError):
    """A command is not 4 finite currents."""


class Tick(NamedTuple):
    """What :meth:`SimulationSession.tick` did.

    Attributes
    ----------
    batch : SampleBatch or None
        The samples to publish.
    note : str
        A line to log ('' when nothing worth it happened).
    warning : bool
        The note reports a problem (a lockstep timeout), not progress.
    """

    batch: SampleBatch | None
    note: str = ''
    warning: bool = False


class SimulationSession:
    """Pacing, commands and run state of a simulation (see the module docstring).

    Parameters
    ----------
    simulator : Simulator
        The physics simulator; the session resets it.
    mode : {'realtime', 'lockstep'}
        Timing mode.
    pace_period : float, optional
        Real time: s of wall time per burst of samples (0: every sample).
    command_timeout : float, optional
        Lockstep: s to wait for a sample's command before holding the last one.
    paused : bool, optional
        Start paused.
    now : float, optional
        Monotonic time at creation, s (default ``time.monotonic()``), the
        start of the first real-time factor interval.
    average : int, optional
        Steps per returned sample, each sample their mean (real time only;
        module docstring). 1: every step is a sample.

    Attributes
    ----------
    counters : dict of str to int
        ``COUNTERS``: samples returned, commands taken and rejected, late
        commands, held samples, timeouts, overruns, crashes, resets.
    real_time_factor : float
        Simulated over wall time in the last :meth:`measure_real_time_factor`
        interval (NaN before the first).

    Raises
    ------
    ValueError
        On an unknown mode, a negative period or timeout, or averaging in lockstep.
    """

    def __init__(
        self,
        simulator: Simulator,
        mode: str,
        *,
        pace_period: float = 0.001,
        command_timeout: float = 1.0,
        paused: bool = False,
        now: float | None = None,
        average: int = 1,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f'mode must be one of {", ".join(MODES)}, got {mode!r}')
        self.averager = SampleAverager(average)
        if average > 1 and mode != 'realtime':
            raise ValueError(
                f'average {average} (samples as means of steps) needs mode realtime, got {mode!r}'
            )
        if not (math.isfinite(pace_period) and pace_period >= 0):
            raise ValueError(f'pace_period must be a finite number >= 0, got {pace_period!r}')
        if not (math.isfinite(command_timeout) and command_timeout > 0):
            raise ValueError(
                f'command_timeout must be a finite number > 0, got {command_timeout!r}'
            )
        self.sim = simulator
        self.mode = mode
        self.command_timeout = float(command_timeout)
        self.dt = 1.0 / simulator.sample_rate
        self.dt_ns = 1e9 * self.dt
        # samples stepped per real-time wake-up: waking 5000 times a second costs
        # more than the step itself; the board's driver also publishes in bursts
        self.burst = max(1, int(round(pace_period / self.dt)))
        #: real time: most samples a pace() call steps (None: all that are due)
        self.max_batch: int | None = None
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.paused = bool(paused)
        self.started = False
        self.real_time_factor = float('nan')
        #: samples returned after the one the last stamped command answered (None: none yet)
        self.command_lag: int | None = None
        self.run_start_ns = 0  # simulated time of the current run's sample 0
        self.last_stamp_ns = -1  # of the last sample returned
        self.waiting_since = 0.0  # lockstep: when the last sample was returned
        self._command = _ZERO.copy()  # the command held for the next step
        self._queue: deque[np.ndarray] = deque()  # lockstep: commands not yet used
        self._steps_since_command = 0
        self._got_command = False
        self._pace: tuple[float, int] | None = None  # real time: origin, samples since
        self._rate_mark = (time.monotonic() if now is None else now, 0)
        self._pending: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        self._crash_pending = False
        self._pause_after: int | None = None  # the run's sample index to pause after
        self._first_reading = simulator.reset()
        self.last_state = simulator.state

    # -- run state --------------------------------------------------------------

    @property
    def crashed(self) -> bool:
        """True after a crash, until :meth:`reset`."""
        return self.sim.crashed

    @property
    def running(self) -> bool:
        """Started, not paused and not crashed."""
        return self.started and not self.paused and not self.sim.crashed

    def start(self, now: float) -> SampleBatch:
        """Start the run: return its current sample (sample 0 after a reset).

        Parameters
        ----------
        now : float
            Monotonic time, s.

        Returns
        -------
        SampleBatch
            One sample.
        """
        self.started = True
        self.waiting_since = now
        return self._first_sample()

    def set_paused(self, paused: bool, now: float) -> SampleBatch | None:
        """Pause (True) or resume (False); lockstep: resuming steps queued commands.

        Parameters
        ----------
        paused : bool
            The new state.
        now : float
            Monotonic time, s.

        Returns
        -------
        SampleBatch or None
            The samples of the queued commands, if any.
        """
        self.paused = bool(paused)
        if not self.paused and self.started and self.mode == 'lockstep':
            return self._advance(now)
        return None

    def pause_after(self, index: int | None) -> None:
        """Pause by itself once the run's sample ``index`` was stepped (None: never).

        The sample itself is returned (published); the commands after it wait
        in the queue until :meth:`set_paused` resumes. Lockstep then steps
        exactly the samples up to ``index``. A sample already stepped pauses
        at once. The setting is cleared when it pauses.

        Parameters
        ----------
        index : int or None
            Index of a sample of the current run (sample 0 is the run's first).
        """
        self._pause_after = None if index is None else int(index)
        if self._pause_after is not None and self.sim.samples >= self._pause_after:
            self._pause_after = None
            self.paused = True

    def reset(self, now: float) -> SampleBatch | None:
        """Restart from the initial state (recovers a crash).

        The new run starts one sample period after the last returned sample;
        queued commands are dropped and the held command is zero.

        Parameters
        ----------
        now : float
            Monotonic time, s.

        Returns
        -------
        SampleBatch or None
            The new run's sample 0 once started, else None (:meth:`start`
            returns it).
        """
        self.run_start_ns = self.last_stamp_ns + int(round(self.dt_ns))
        self._first_reading = self.sim.reset()
        self.averager.reset()
        self._queue.clear()
        self._command = _ZERO.copy()
        self._steps_since_command = 0
        self._got_command = False
        self.counters['resets'] += 1
        self.last_state = self.sim.state
        if not self.started:
            return None
        self.waiting_since = now
        return self._first_sample()

    # -- commands ---------------------------------------------------------------

    def command(self, values, now: float, stamp_ns: int | None = None) -> SampleBatch | None:
        """Take a command: 4 coil currents (or drives), A, order x+ x- y+ y-.

        Real time: held from the next step on. Lockstep: queued; every queued
        command steps one sample while running.

        Parameters
        ----------
        values : array_like, shape (4,)
            The command.
        now : float
            Monotonic time, s.
        stamp_ns : int, optional
            Stamp of the sample the command answers, ns: its lag behind the
            newest returned sample becomes :attr:`command_lag` (samples).

        Returns
        -------
        SampleBatch or None
            Lockstep: the samples stepped. Real time: None.

        Raises
        ------
        CommandError
            If ``values`` are not 4 finite numbers (counted, nothing changes).
        """
        values = np.asarray(values, dtype=float)
        if values.shape != (4,) or not np.all(np.isfinite(values)):
            self.counters['commands_rejected'] += 1
            raise CommandError(
                f'need 4 finite currents (x+, x-, y+, y-), got {values.ravel().tolist()}'
            )
        self.counters['commands'] += 1
        if stamp_ns is not None:
            self.command_lag = round((self.last_stamp_ns - stamp_ns) / self.dt_ns)
        if self.mode == 'realtime':
            if self._steps_since_command > 1:
                self.counters['late_commands'] += 1
            self._steps_since_command = 0
            self._got_command = True
            self._command = values
            return None
        if not self.started:
            return None  # before the first sample: not a command for any sample
        self._queue.append(values)
        return self._advance(now)

    def check_timeout(self, now: float) -> SampleBatch | None:
        """Lockstep: past ``command_timeout`` without a command, hold the last one.

        Parameters
        ----------
        now : float
            Monotonic time, s.

        Returns
        -------
        SampleBatch or None
            The sample stepped with the held command (a timeout), else None.
        """
        if self.mode != 'lockstep' or not self.running:
            return None
        if now - self.waiting_since <= self.command_timeout:
            return None
        self.counters['timeouts'] += 1
        self._step(self._command)
        return self._awaiting_from(now)

    def tick(self, now: float, ready: Callable[[], bool]) -> Tick:
        """Do what is due at ``now``: start, a lockstep timeout, or a real-time burst.

        Call it periodically (real time: every ``pace_period``; lockstep: a
        fraction of ``command_timeout``). Paused or crashed, nothing is due.
        Not started, the run starts once ``ready()`` (the caller's peers are
        there) and, in real time, a first command came. Started, lockstep
        holds the last command past ``command_timeout`` (:meth:`check_timeout`)
        and real time steps the samples due (:meth:`pace`).

        Parameters
        ----------
        now : float
            Monotonic time, s.
        ready : callable
            Returns whether the peers the run waits for are there; asked
            only before the start.

        Returns
        -------
        Tick
            The samples to publish, and a line to log: the start (info) or a
            lockstep timeout (a warning).
        """
        if self.paused or self.sim.crashed:
            self._pace = None  # real-time pacing restarts on resume
            return Tick(None)
        if not self.started:
            if (self.mode == 'realtime' and not self.counters['commands']) or not ready():
                return Tick(None)
            return Tick(self.start(now), f'started: stepping in {self.mode}')
        if self.mode == 'realtime':
            return Tick(self.pace(now)[0])
        age = now - self.waiting_since
        batch = self.check_timeout(now)
        if batch is None:
            return Tick(None)
        return Tick(batch, timeout_line(self, age), warning=True)

    def _advance(self, now: float) -> SampleBatch | None:
        """Lockstep: step once per queued command while running."""
        while self._queue and not self.paused and not self.sim.crashed:
            self._command = self._queue.popleft()
            self._step(self._command)
        return self._awaiting_from(now)

    def _awaiting_from(self, now: float) -> SampleBatch | None:
        """Lockstep: wait for the next command from ``now``; return the pending samples."""
        self.waiting_since = now
        return self._take()

    # -- real time --------------------------------------------------------------

    def pace(self, now: float) -> tuple[SampleBatch | None, float]:
        """Real time: step the samples due at wall time ``now``.

        Call it in a loop, waiting the returned time between calls. Samples
        are stepped once a whole burst is due; more than ``MAX_BACKLOG_S``
        behind, one sample is stepped and pacing restarts at ``now`` (the
        backlog is dropped, an overrun counted).

        Parameters
        ----------
        now : float
            Monotonic time, s.

        Returns
        -------
        batch : SampleBatch or None
            The samples stepped (None: none due, paused or crashed).
        wait : float
            s from ``now`` to the next burst (after a burst too: stepping
            takes part of it; 0 when behind: call again at once).

        Notes
        -----
        With :attr:`max_batch` set, a call steps at most that many samples
        (behind, the next call follows at once): a loop closed in the same
        thread answers each burst before the next is stepped.
        """
        if self.paused or self.sim.crashed:
            self._pace = None  # pacing restarts on resume
            return None, PAUSED_POLL_S
        base, done = self._pace if self._pace is not None else (now, 0)
        dt = self.dt
        due = int((now - base) / dt) - done
        if due < self.burst:
            self._pace = (base, done)
            return None, max(base + (done + self.burst) * dt - now, 0.0)
        if due * dt > MAX_BACKLOG_S:
            self.counters['overruns'] += 1
            base, done = now - dt, 0
            due = 1
        if self.max_batch is not None:
            due = min(due, self.max_batch)
        before = self.sim.samples
        batch = self._burst(due)
        done += self.sim.samples - before  # steps, the crashing one too (a batch may average)
        self._pace = (base, done)
        return batch, max(base + (done + self.burst) * dt - now, 0.0)

    def _burst(self, count: int) -> SampleBatch:
        """Step up to ``count`` samples with the held command (fewer on a crash)."""
        for _ in range(count):
            if self._got_command and self._steps_since_command >= 1:
                self.counters['held_samples'] += 1
            self._steps_since_command += 1
            if not self._step(self._command) or self.paused:  # a crash, or pause_after
                break
        return self._take()

    # -- measuring --------------------------------------------------------------

    def measure_real_time_factor(self, now: float) -> float:
        """Measure simulated over wall time since the previous call, while running.

        Parameters
        ----------
        now : float
            Monotonic time, s.

        Returns
        -------
        float
            The new factor, or the previous one when not running (NaN at first).
        """
        then, samples = self._rate_mark
        self._rate_mark = (now, self.counters['samples'])
        if self.running:
            self.real_time_factor = (
                (self.counters['samples'] - samples) * self.dt / max(now - then, 1e-9)
            )
        return self.real_time_factor

    # -- stepping ---------------------------------------------------------------

    def _step(self, command: np.ndarray) -> bool:
        """Step one sample into the pending batch; False on a crash."""
        sim = self.sim
        reading = sim.step(command)
        if sim.crashed:
            self.counters['crashes'] += 1
            self._crash_pending = True
            return False
        self._pending.append((sim.samples, reading, sim.state, sim.currents))
        if self._pause_after is not None and sim.samples >= self._pause_after:
            self._pause_after = None
            self.paused = True
        return True

    def _first_sample(self) -> SampleBatch:
        sim = self.sim
        self._pending.append((sim.samples, self._first_reading, sim.state, sim.currents))
        return self._take()

    def _take(self) -> SampleBatch | None:
        """Return the pending samples as a batch (None if nothing happened)."""
        pending, crashed = self._pending, self._crash_pending
        if not pending and not crashed:
            return None
        self._pending, self._crash_pending = [], False
        n = len(pending)
        columns = list(zip(*pending, strict=True))  # index, reading, state, currents of each
        indices = np.array(columns[0] if n else (), dtype=np.int64)
        if n:
            readings, states, currents = (np.array(columns[k]) for k in (1, 2, 3))
        else:
            readings = np.empty((0, len(self._first_reading)))
            states, currents = np.empty((0, 12)), np.empty((0, 4))
        stamps = self.run_start_ns + np.rint(indices * self.dt_ns).astype(np.int64)
        if n:
            self.last_state = states[-1]
            self.last_stamp_ns = int(stamps[-1])
            self.counters['samples'] += n
        if crashed:
            self.last_state = self.sim.crash_state
        batch = self.averager.add(
            SampleBatch(indices, stamps, readings, states, currents, crashed)
        )
        return batch if len(batch) or crashed else None


def timeout_line(session: SimulationSession, age: float) -> str:
    """Describe a lockstep command timeout in one log line.

    Parameters
    ----------
    session : SimulationSession
        The session that held the last command.
    age : float
        s since the previous sample was returned.

    Returns
    -------
    str
        One line.
    """
    return (
        f'no command for {age:.3f} s > {session.command_timeout} s at '
        f't = {session.sim.time:.6f} s: holding the last command'
    )
