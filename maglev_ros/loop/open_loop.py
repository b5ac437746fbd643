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
        """Ignored: the open loop has no set-point."""

    def command(self, t: float, reading=None, currents=None) -> np.ndarray:
        """Return zero currents, shape (n_s,), A."""
        return self._zero.copy()

    def status(self) -> ControllerStatus:
        """Return the status: always OK."""
        return ControllerStatus('OK', 'open loop', True, 0, 0)
