"""What the control loop reads from and writes to: a plant, simulated or a board.

The ros2_control shape: the loop does not know which plant it runs. A plant
returns the samples that came since the last read (:class:`SampleBlock`) and
takes one command at a time. Lockstep plants step one sample per command; real
plants (a board, or a simulator paced by the wall clock) return whatever
arrived.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ['Plant', 'SampleBlock']


@dataclass(frozen=True)
class SampleBlock:
    """The samples of one read, oldest first (n samples, k sensors, n_s coils).

    Attributes
    ----------
    index : ndarray of int, shape (n,)
        Sample numbers of the run (0 is the run's first).
    times : ndarray, shape (n,)
        Sample times, s (the plant's clock: simulated, or the board's mapped
        onto the host's): what the estimator and the controller are given.
    stamps_ns : ndarray of int64, shape (n,)
        The same times as message stamps, ns.
    readings : ndarray, shape (n, 3 k)
        Sensor fields, T, sensor by sensor (x, y, z each).
    currents : ndarray, shape (n, n_s)
        Coil currents, A, order x+, x-, y+, y-.
    valid : ndarray of bool, shape (n,)
        False where the sample's readings did not arrive (the estimator then
        predicts only and the controller sees no input).
    states : ndarray, shape (n, 12), optional
        True state at each sample (simulated plants only).
    crashed : bool
        The plant stopped: the magnet was lost (simulated) or the link failed.
    reason : str
        Why it stopped.
    """

    index: np.ndarray
    times: np.ndarray
    stamps_ns: np.ndarray
    readings: np.ndarray
    currents: np.ndarray
    valid: np.ndarray
    states: np.ndarray | None = field(default=None, repr=False)
    crashed: bool = False
    reason: str = ''

    def __len__(self) -> int:
        return int(self.index.shape[0])


@runtime_checkable
class Plant(Protocol):
    """A sampled plant: read a block of samples, write a command, close.

    Attributes
    ----------
    sample_rate : float
        Samples per second, Hz.
    n_inputs : int
        Coils commanded (4: x+, x-, y+, y-).
    lockstep : bool
        True when the plant steps exactly one sample per :meth:`write` (a
        simulation in lockstep); False when samples come on their own clock.
    """

    sample_rate: float
    n_inputs: int
    lockstep: bool

    def read(self) -> SampleBlock:
        """Return the samples since the last read (lockstep: exactly one)."""
        ...

    def write(self, command: np.ndarray, stamp_ns: int) -> None:
        """Apply coil currents, A, shape (n_s,), answering the sample stamped ``stamp_ns``."""
        ...

    def close(self) -> None:
        """Leave the coils at zero current and release the plant."""
        ...
