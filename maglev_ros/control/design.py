"""LQR design on the discretised reduced model, with the loop's delay and the coils' lag.

The controller's state (all known at sample k)::

    xi = [dx (10), i (4) if coil_dynamics, c_prev (4 N) for command_delay N, e (3) if integral]

``dx``: the estimate's deviation from the equilibrium (the estimator has
already predicted across the sensor's sample of delay); ``i``: measured coil
currents (each follows its command with ``L di/dt = R (c - i)``); ``c_prev``:
the commands computed at k-1, ..., k-N, newest first (a shift register): with
commands taking effect N samples late, the one of k-N drives the coils over
k -> k+1; ``e``: the integral of the
position error (m s). The continuous [dx, i] model is discretised exactly
(ZOH) and the gain comes from python-control's ``dlqr``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.discretization import zoh
from .config import ControllerConfig

__all__ = ['LqrDesign', 'design_lqr', 'steady_state']


@dataclass(frozen=True)
class LqrDesign:
    """A discrete LQR design.

    Attributes
    ----------
    K : ndarray, shape (m, n)
        Gain: ``c = c_ss - K (xi - xi_ss)``.
    A, B : ndarray, shape (n, n), (n, m)
        Discrete augmented model.
    Q, R : ndarray
        Weights used.
    poles : ndarray, shape (n,)
        Closed-loop eigenvalues (z-plane).
    layout : dict
        Slices of ``xi``: ``dx``, ``i``, ``c_prev``, ``e`` (absent parts omitted).
    tau : float
        Coil time constant used, s (0 without coil dynamics).
    """

    K: np.ndarray
    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    poles: np.ndarray
    layout: dict
    tau: float

    @property
    def stable(self) -> bool:
        """True when every closed-loop pole lies inside the unit circle."""
        return bool(np.all(np.abs(self.poles) < 1.0))


def steady_state(
    A: np.ndarray, B: np.ndarray, position: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Equilibrium deviation and currents that hold a position offset.

    Solves ``A dx + B u = 0`` with ``dx[:3] = position`` (least norm in u).

    Parameters
    ----------
    A : ndarray, shape (10, 10)
    B : ndarray, shape (10, m)
    position : ndarray, shape (3,)
        Offset from the equilibrium, m.

    Returns
    -------
    dx : ndarray, shape (10,)
    u : ndarray, shape (m,)
    """
    n, m = B.shape
    top = np.hstack([A, B])
    sel = np.zeros((3, n + m))
    sel[:, :3] = np.eye(3)
    lhs = np.vstack([top, sel])
    rhs = np.concatenate([np.zeros(n), position])
    # scale the rows so that the least-squares problem is well conditioned
    scale = 1.0 / np.maximum(np.abs(lhs).max(axis=1), 1e-300)
    sol = np.linalg.lstsq(lhs * scale[:, None], rhs * scale, rcond=None)[0]
    return sol[:n], sol[n:]


def design_lqr(linear, config: ControllerConfig, tau: float = 0.0) -> LqrDesign:
    """LQR gain for the reduced linear model at the control rate.

    Parameters
    ----------
    linear : LinearModel
        Reduced (10-state) continuous linearisation.
    config : ControllerConfig
        Rate, delay, coil dynamics, integral action and Bryson scales.
    tau : float
        Coil time constant L / R, s (used when ``config.coil_dynamics``).

    Returns
    -------
    LqrDesign

    Raises
    ------
    ValueError
        When the design has no stabilising solution.
    """
    import control

    a = np.asarray(linear.A, dtype=float)
    b = np.asarray(linear.B, dtype=float)
    nx, m = b.shape
    dt = config.dt
    use_coil = config.coil_dynamics and tau > 0
    if use_coil:
        ac = np.zeros((nx + m, nx + m))
        ac[:nx, :nx] = a
        ac[:nx, nx:] = b
        ac[nx:, nx:] = -np.eye(m) / tau
        bc = np.zeros((nx + m, m))
        bc[nx:] = np.eye(m) / tau
    else:
        ac, bc = a, b
    phi, gamma = zoh(ac, bc, dt)
    n_plant = phi.shape[0]
    layout = {'dx': slice(0, nx)}
    if use_coil:
        layout['i'] = slice(nx, nx + m)
    delay = config.command_delay
    if delay:
        n1 = n_plant + delay * m
        A1 = np.zeros((n1, n1))
        A1[:n_plant, :n_plant] = phi
        A1[:n_plant, n1 - m :] = gamma  # the oldest pending command drives the plant
        A1[n_plant + m :, n_plant : n1 - m] = np.eye((delay - 1) * m)  # the register shifts
        B1 = np.zeros((n1, m))
        B1[n_plant : n_plant + m] = np.eye(m)  # the new command enters first
        layout['c_prev'] = slice(n_plant, n1)
    else:
        A1, B1 = phi, gamma
    n1 = A1.shape[0]
    if config.integral:
        n2 = n1 + 3
        A2 = np.eye(n2)
        A2[:n1, :n1] = A1
        A2[n1:, :3] = dt * np.eye(3)
        B2 = np.vstack([B1, np.zeros((3, m))])
        layout['e'] = slice(n1, n2)
    else:
        A2, B2 = A1, B1
    c = config
    q = np.zeros(A2.shape[0])
    q[:3] = c.position_scale**-2
    q[3:5] = c.angle_scale**-2
    q[5:8] = c.velocity_scale**-2
    q[8:10] = c.rate_scale**-2
    if 'e' in layout:
        q[layout['e']] = c.integral_scale**-2
    Q = np.diag(q)
    R = np.eye(m) * c.current_scale**-2
    try:
        # scipy's solver: slycot's (used when installed) refuses this scaling as inaccurate
        K, _, poles = control.dlqr(A2, B2, Q, R, method='scipy')
    except Exception as exc:  # noqa: BLE001 - slycot/scipy raise various types
        raise ValueError(f'LQR design failed: {exc}') from None
    K = np.asarray(K, dtype=float)
    return LqrDesign(
        K=K,
        A=A2,
        B=B2,
        Q=Q,
        R=R,
        poles=np.asarray(poles),
        layout=layout,
        tau=float(tau) if use_coil else 0.0,
    )
