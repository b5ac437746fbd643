"""The open loop as a controller of the control loop: zero commands, the excitation on top.

With :class:`OpenLoop` as its controller (and no estimator) the
:class:`~maglev_ros.loop.ControlLoop` writes exactly the excitation: the lab
session (:func:`~maglev_ros.loop.run_session`) then records an open-loop
experiment (a fixed or absent magnet, a board driven by its excitation) the
way it records a closed-loop one.
"""

from __future__ import annotations

import numpy as np

from ..control.safety import ControllerStatus

__all__ = ['OpenLoop']


class OpenLoop:
    """A controller that commands zero current (always active: the excitation is added).

    Parameters
    ----------
    n_inputs : int
        Coils commanded.
    """

    active = True

    def __init__(self, n_inputs: int = 4) -> None:
        self._zero = np.zeros(n_inputs)

    def reset(self) -> None:
        """Nothing to reset."""

    def set_reference(self, position=None) -> None:
        """Ignore a set-point: the open loop has none.

        Parameters
        ----------
        position : array_like, shape (3,), optional
            m (not used).
        """

    def command(self, t: float, reading=None, currents=None) -> np.ndarray:
        """Return zero currents, shape (n_s,), A.

        Parameters
        ----------
        t : float
            Sample time, s (not used).
        reading : ndarray, shape (3 k,), optional
            The sample's fields, T (not used).
        currents : ndarray, shape (n_s,), optional
            The sample's coil currents, A (not used).
        """
        return self._zero.copy()

    def status(self) -> ControllerStatus:
        """Return the status: always OK."""
        return ControllerStatus('OK', 'open loop', True, 0, 0)
