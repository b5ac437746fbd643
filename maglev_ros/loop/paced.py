"""The physics simulator as a real-time plant: bursts of samples paced by the wall clock."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .plant import SampleBlock
from .simulated import _empty

__all__ = ['PacedSimulatedPlant']


class PacedSimulatedPlant:
    """A :class:`~maglev_ros.physics.Simulator` that runs on a clock, as a board does.

    Each :meth:`read` waits until the next burst of samples is due (``burst``
    samples, one control period), steps the simulator through them with the
    command held since the last :meth:`write`, and returns them. A loop that
    fell behind gets every sample that fell due meanwhile (at most
    ``max_burst``; the rest are skipped and counted as ``overruns``), so
    simulated time keeps pace with the clock.

    Parameters
    ----------
    simulator : Simulator
        The plant.
    burst : int
        Samples per read (sample rate / control rate).
    clock : callable, optional
        Monotonic time, s (default :func:`time.monotonic`).
    sleep : callable, optional
        Waits a number of seconds (default :func:`time.sleep`); a simulated
        clock's sleep advances it.
    max_burst : int, optional
        Most samples returned by one read (default ``10 * burst``).
    """

    lockstep = False

    def __init__(
        self,
        simulator,
        burst: int,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        max_burst: int | None = None,
    ) -> None:
        if isinstance(burst, bool) or not isinstance(burst, int) or burst < 1:
            raise ValueError(f'burst must be an integer >= 1, got {burst!r}')
        self.simulator = simulator
        self.burst = burst
        self.max_burst = max_burst or 10 * burst
        self.sample_rate = 1.0 / simulator.dt
        self.n_inputs = simulator.model.n_inputs
        self.clock = clock
        self.sleep = sleep
        self.overruns = 0
        self.start: float | None = None  # clock time of sample 0 (moves on a skip ahead)
        self._origin = 0.0  # clock time of the first read
        self._command = np.zeros(self.n_inputs)
        self._dt_ns = 1e9 * simulator.dt
        simulator.reset()

    def reset(self, x0=None) -> None:
        """Restart the simulation at ``x0``; the clock restarts at the next read.

        Parameters
        ----------
        x0 : array_like, shape (12,), optional
            Initial state (default: the equilibrium).
        """
        self.simulator.reset(x0)
        self.start = None
        self._command = np.zeros(self.n_inputs)

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per clock second since the first read (NaN before)."""
        if self.start is None:
            return float('nan')
        return self.simulator.time / max(self.clock() - self._origin, 1e-9)

    def read(self) -> SampleBlock:
        """Wait for the next burst, step it with the held command and return its samples."""
        sim = self.simulator
        if sim.crashed:
            return _empty(self.n_inputs, sim.model.n_outputs, sim.reason, sim.crash_time)
        if self.start is None:
            self.start = self._origin = self.clock()
        due_at = self.start + (sim.samples + self.burst) * sim.dt
        wait = due_at - self.clock()
        if wait > 0:
            self.sleep(wait)
        due = int((self.clock() - self.start) / sim.dt) - sim.samples
        n = min(max(due, self.burst), self.max_burst)
        if due > self.max_burst:  # far behind: skip ahead, the magnet does not wait
            self.overruns += 1
            self.start += (due - n) * sim.dt
        index = np.empty(n, dtype=np.int64)
        readings = np.empty((n, sim.model.n_outputs))
        currents = np.empty((n, self.n_inputs))
        states = np.empty((n, 12))
        done = 0
        for j in range(n):
            readings[j] = sim.step(self._command)
            if sim.crashed:
                break
            index[j] = sim.samples
            currents[j] = sim.currents
            states[j] = sim.state
            done += 1
        times = index[:done] * sim.dt
        return SampleBlock(
            index=index[:done],
            times=times,
            stamps_ns=np.rint(index[:done] * self._dt_ns).astype(np.int64),
            readings=readings[:done],
            currents=currents[:done],
            valid=np.ones(done, dtype=bool),
            states=states[:done],
            crashed=sim.crashed,
            reason=f'{sim.reason} at t = {sim.crash_time:.4f} s' if sim.crashed else '',
        )

    def write(self, command: np.ndarray, stamp_ns: int) -> None:
        """Hold ``command`` from the next sample on.

        Parameters
        ----------
        command : ndarray, shape (n_s,)
            Coil currents, A, order x+, x-, y+, y-.
        stamp_ns : int
            Stamp of the sample the command answers, ns.
        """
        self._command = np.array(command, dtype=float)

    def close(self) -> None:
        """Nothing to release: a simulation has no coils to zero."""
