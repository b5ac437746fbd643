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
    """

    lockstep = True

    def __init__(self, simulator, cut: tuple[float, float] | None = None) -> None:
        self.simulator = simulator
        self.sample_rate = 1.0 / simulator.dt
        self.n_inputs = simulator.model.n_inputs
        self._dt_ns = 1e9 * simulator.dt
        self._cut = (cut[0], cut[0] + cut[1]) if cut else (np.inf, -np.inf)
        self._reading = simulator.reset()

    def reset(self, x0=None) -> None:
        """Restart the simulation at ``x0`` (shape (12,); default: its equilibrium)."""
        self._reading = self.simulator.reset(x0)

    def read(self) -> SampleBlock:
        """Return the current sample (an empty block once the magnet is lost)."""
        sim = self.simulator
        if sim.crashed:
            return _empty(self.n_inputs, self._reading.shape[0], sim.reason, sim.crash_time)
        k = sim.samples
        t = sim.time
        valid = _FALSE if self._cut[0] <= t < self._cut[1] else _TRUE
        return SampleBlock(
            index=np.array([k]),
            times=np.array([t]),
            stamps_ns=np.array([round(k * self._dt_ns)], dtype=np.int64),
            readings=self._reading[None, :],
            currents=sim.currents[None, :],
            valid=valid,
            states=sim.state[None, :],
        )

    def write(self, command: np.ndarray, stamp_ns: int) -> None:
        """Step one sample with ``command`` (A, shape (n_s,)) held."""
        self._reading = self.simulator.step(command)

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
