"""Exact zero-order-hold discretisation of continuous linear models."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

__all__ = ['zoh']


def zoh(A, B, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of dx/dt = A x + B u.

    Computed from one matrix exponential of the block matrix ``[[A, B], [0, 0]] dt``
    (Van Loan), which stays exact when A is singular.

    Parameters
    ----------
    A : array_like, shape (n, n)
        Continuous state matrix, 1/s.
    B : array_like, shape (n, m)
        Continuous input matrix.
    dt : float
        Sample period, s (> 0).

    Returns
    -------
    Ad : ndarray, shape (n, n)
        ``exp(A dt)``.
    Bd : ndarray, shape (n, m)
        ``integral_0^dt exp(A s) ds B``.
    """
    a = np.atleast_2d(np.asarray(A, dtype=float))
    b = np.asarray(B, dtype=float).reshape(a.shape[0], -1)
    if a.shape[0] != a.shape[1]:
        raise ValueError(f'A must be square, got shape {a.shape}')
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f'dt must be positive, got {dt!r}')
    n, m = b.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = a
    block[:n, n:] = b
    phi = expm(block * dt)
    return phi[:n, :n], phi[:n, n:]
