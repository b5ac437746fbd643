"""Compiled (numba) control law: one call per sample."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ['lqr_law']


@njit(cache=True)
def lqr_law(x, i, c_prev, e, Kx, Ki, Kc, Ke, bias, limit):  # pragma: no cover - jitted
    """``c = bias - Kx x - Ki i - Kc c_prev - Ke e``, clipped at +-``limit``.

    Parameters
    ----------
    x : ndarray, shape (12,)
        Estimated full state.
    i : ndarray, shape (m,)
        Measured coil currents, A.
    c_prev : ndarray, shape (N m,)
        The pending commands, newest first, A.
    e : ndarray, shape (3,)
        Integrated position error, m s.
    Kx : ndarray, shape (m, 12)
        The gain on the full state (zero columns for gamma and wz).
    Ki : ndarray, shape (m, m)
    Kc : ndarray, shape (m, N m)
    Ke : ndarray, shape (m, 3)
        Gains (zero when the design has no such state).
    bias : ndarray, shape (m,)
        ``u_ss + Kx x_ss + Ki u_ss + Kc [u_ss ... u_ss]``: the set-point's share.
    limit : float
        A.

    Returns
    -------
    command : ndarray, shape (m,)
    saturated : bool
    """
    m = bias.shape[0]
    out = np.empty(m)
    saturated = False
    for r in range(m):
        acc = bias[r]
        for j in range(x.shape[0]):
            acc -= Kx[r, j] * x[j]
        for j in range(m):
            acc -= Ki[r, j] * i[j]
        for j in range(c_prev.shape[0]):
            acc -= Kc[r, j] * c_prev[j]
        for j in range(3):
            acc -= Ke[r, j] * e[j]
        if acc > limit:
            acc = limit
            saturated = True
        elif acc < -limit:
            acc = -limit
            saturated = True
        out[r] = acc
    return out, saturated
