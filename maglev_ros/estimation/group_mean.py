"""The mean of N readings taken over a sample, as one linear measurement of its start.

A sensor read at N times the sample rate whose sample is the mean of its N
readings (the simulator's ``average``) does not read one state: its readings
are of the states ``x_0, x_1, ..., x_{N-1}`` at the sensing period
``Ts = dt / N`` from the sample's start. With the linear model at the sensing
period, ``x_{i+1} = A_s x_i + B_s u`` and ``y_i = C x_i + D u``, and the input
(the coil currents) held over the sample, the mean is exactly linear in the
state at the sample's start and the input::

    mean_i y_i = C_bar x_0 + D_bar u
    C_bar = C mean_i A_s^i
    D_bar = D + C mean_i (sum_{l<i} A_s^l) B_s

(the second term of D_bar: how far the input moves the magnet within the
sample). A bias adds to every reading, so to the mean unchanged. Independent
noise of variance ``r`` per reading (quantisation included: the sensor noise
dithers it) leaves ``r / N`` on the mean.
"""

from __future__ import annotations

import numpy as np

from ..physics.discretization import zoh

__all__ = ['group_mean_model']


def group_mean_model(A, B, C, D, dt: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Return ``C_bar`` and ``D_bar`` of the mean of ``n`` readings over a sample (module doc).

    Parameters
    ----------
    A : array_like, shape (r, r)
        Continuous state matrix, 1/s.
    B : array_like, shape (r, m)
        Continuous input matrix.
    C : array_like, shape (p, r)
        Output matrix, T per state unit.
    D : array_like, shape (p, m)
        Feedthrough, T/A.
    dt : float
        Sample period, s (the mean's readings are ``dt / n`` apart, the first at
        the sample's start).
    n : int
        Readings per mean (1: ``C`` and ``D`` unchanged).

    Returns
    -------
    C_bar : ndarray, shape (p, r)
    D_bar : ndarray, shape (p, m)

    Raises
    ------
    ValueError
        If ``n`` is not an integer >= 1.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f'readings per mean must be an integer >= 1, got {n!r}')
    C = np.asarray(C, dtype=float)
    D = np.asarray(D, dtype=float)
    a_s, b_s = zoh(A, B, dt / n)
    r = a_s.shape[0]
    power = np.eye(r)  # A_s^i
    gamma = np.zeros_like(b_s)  # sum_{l<i} A_s^l B_s: the input's response after i readings
    sum_power = np.zeros((r, r))
    sum_gamma = np.zeros_like(b_s)
    for _ in range(n):
        sum_power += power
        sum_gamma += gamma
        gamma = gamma + power @ b_s
        power = power @ a_s
    return C @ sum_power / n, D + C @ sum_gamma / n
