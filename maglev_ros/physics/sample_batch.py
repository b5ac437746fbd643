"""The samples a simulation step produced, as the simulator publishes them (ROS-free)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['SampleBatch']


@dataclass(frozen=True)
class SampleBatch:
    """Samples to publish, in order (n may be 0 when only a crash happened).

    Attributes
    ----------
    indices : ndarray of int64, shape (n,)
        Sample numbers within the run (0: the run's initial sample).
    stamps_ns : ndarray of int64, shape (n,)
        Simulated time of each sample, ns.
    readings : ndarray, shape (n, 3 K)
        Sensor readings of all K sensors of the parameter set, T.
    states : ndarray, shape (n, 12)
        State after each sample: position (m), ZYX Euler angles (rad), world
        velocity (m/s), body rates (rad/s).
    currents : ndarray, shape (n, 4)
        Coil currents, A (x+ x- y+ y-).
    crashed : bool
        The integration crashed after these samples (the crashing step is not
        among them; see the simulator's ``crash_time`` and ``reason``).
    """

    indices: np.ndarray
    stamps_ns: np.ndarray
    readings: np.ndarray
    states: np.ndarray
    currents: np.ndarray
    crashed: bool = False

    def __len__(self) -> int:
        return int(self.indices.shape[0])
