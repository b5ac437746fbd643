"""The physics simulator as a lockstep plant: one sample per command."""

from __future__ import annotations

import numpy as np

from .plant import SampleBlock

__all__ = ['SimulatedPlant']

_TRUE = np.ones(1, dtype=bool)
_FALSE = np.zeros(1, dtype=bool)


class SimulatedPlant:
    """A :class:`~maglev_ros.physics.Simulator` stepped once per command (lockstep).

    :meth:`read` returns the current sample: its reading (the simulator's, with
    its noise, quantisation and sensor delay), coil currents and true state.
    :meth:`write` holds the command over the next sample period and steps.

    Parameters
    ----------
    simulator : Simulator
        The plant; :meth:`reset` restarts it.
    cut : (start, length) in s, optional
        Readings lost over this interval (``valid`` False): the estimator
        predicts only and the controller sees no input.
    average : int, optional
        Simulator steps per sample (1: one). With N > 1 a sample is the mean
        of N readings (and of the coil currents), the simulator runs at N
        times the plant's rate, and the sample's stamp and state are the
        group's last (:class:`~maglev_ros.physics.sample_average.SampleAverager`,
        as the simulator node's ``average``).
    offset : int, optional
        With ``average``: steps of each group that still hold the previous
        command before the new one applies (0 .. N-1; 0: at the group's
        start). Where a command lands in a real-time group of separate
        processes is not known: this sets it.
    """

    lockstep = True

    def __init__(
        self,
        simulator,
        cut: tuple[float, float] | None = None,
        average: int = 1,
        offset: int = 0,
    ) -> None:
        from ..physics.sample_average import SampleAverager

        self.averager = SampleAverager(average)
        if isinstance(offset, bool) or offset not in range(self.averager.n):
            raise ValueError(f'offset must be an integer from 0 to {average - 1}, got {offset!r}')
        self.average, self.offset = self.averager.n, offset
        self.simulator = simulator
        self.sample_rate = 1.0 / (simulator.dt * self.average)
        self.n_inputs = simulator.model.n_inputs
        self._dt_ns = 1e9 * simulator.dt
        self._cut = (cut[0], cut[0] + cut[1]) if cut else (np.inf, -np.inf)
        self._reading = simulator.reset()
        self._currents = simulator.currents
        self._held = np.zeros(self.n_inputs)  # the command of the last write

    def reset(self, x0=None) -> None:
        """Restart the simulation at ``x0``.

        Parameters
        ----------
        x0 : array_like, shape (12,), optional
            Initial state (default: the equilibrium).
        """
        self._reading = self.simulator.reset(x0)
        self._currents = self.simulator.currents
        self._held = np.zeros(self.n_inputs)

    def read(self) -> SampleBlock:
        """Return the current sample (an empty block once the magnet is lost)."""
        sim = self.simulator
        if sim.crashed:
            return _empty(self.n_inputs, self._reading.shape[0], sim.reason, sim.crash_time)
        k = sim.samples
        t = sim.time
        valid = _FALSE if self._cut[0] <= t < self._cut[1] else _TRUE
        return SampleBlock(
            index=np.array([k // self.average]),
            times=np.array([t]),
            stamps_ns=np.array([round(k * self._dt_ns)], dtype=np.int64),
            readings=self._reading[None, :],
            currents=self._currents[None, :],
            valid=valid,
            states=sim.state[None, :],
        )

    def write(self, command: np.ndarray, stamp_ns: int) -> None:
        """Step one sample with ``command`` held (with ``average``: from ``offset`` on).

        Parameters
        ----------
        command : ndarray, shape (n_s,)
            Coil currents, A, order x+, x-, y+, y-.
        stamp_ns : int
            Stamp of the sample the command answers, ns.
        """
        sim = self.simulator
        if self.average == 1:
            self._reading = sim.step(command)
            self._currents = sim.currents
            return
        from ..physics.session import SampleBatch

        rows = []
        for i in range(self.average):
            reading = sim.step(self._held if i < self.offset else command)
            if sim.crashed:
                break
            rows.append((sim.samples, reading, sim.state, sim.currents))
        self._held = np.array(command, dtype=float)
        if sim.crashed:
            return
        index, readings, states, currents = (np.array(c) for c in zip(*rows, strict=True))
        mean = self.averager.add(SampleBatch(index, index, readings, states, currents))
        self._reading, self._currents = mean.readings[0], mean.currents[0]

    def close(self) -> None:
        """Nothing to release: a simulation has no coils to zero."""


def _empty(n_s: int, n_y: int, reason: str, at: float | None) -> SampleBlock:
    return SampleBlock(
        index=np.empty(0, dtype=np.int64),
        times=np.empty(0),
        stamps_ns=np.empty(0, dtype=np.int64),
        readings=np.empty((0, n_y)),
        currents=np.empty((0, n_s)),
        valid=np.empty(0, dtype=bool),
        states=np.empty((0, 12)),
        crashed=True,
        reason=f'{reason} at t = {at:.4f} s' if at is not None else reason,
    )
