"""The nonlinear filters' model: compiled f and h of the fast field model, built for the budget.

Measurement h: the base's field at the sensors (permanent magnets and coils)
is linear in the coil currents, so it is evaluated once, as a reading
``y0 + G u`` (gain, mounting rotation and offset included); each call then
only adds the levitating magnet's own field at the k sensors (one loop at k
points). The same numbers as ``physics.kernels.fast_measurement`` to
round-off (about 1e-16 T), several times cheaper.

Process f: ``physics.kernels.fast_dynamics``. Two ways over a sample of
length ``dt`` with the currents held (ZOH):

``full``
    one RK4 step (4 evaluations of f), the simulator's integrator.
``fast``
    one exponential-Euler step ``x + dt phi1(A dt) f(x)``, with
    ``phi1(Z) = I + Z / 2 + Z^2 / 6 + Z^3 / 24`` and A the Jacobian of f: one
    evaluation of f. It is exact for a linear model and its error per sample
    is third order in ``dt`` (``|A| dt < 0.05`` at 5 kHz: the magnet's time
    constants are 20 ms and longer against a 0.2 ms sample).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..physics import kernels as phys
from ..physics.loop import AGM_ITERATIONS, MU0
from .kernels import _mm

__all__ = [
    'base_reading',
    'magnet_reading',
    'filter_measurement',
    'measurement_jacobian',
    'series_transition',
    'embed',
]


def base_reading(model) -> tuple[np.ndarray, np.ndarray]:
    """Return the base's part of the readings ``y0 + G u``: y0 (3 k,) T, G (3 k, n_s) T/A.

    Parameters
    ----------
    model : MaggyModel
        A model with the fast field.
    """
    src, coil, sens, mag, work = model.measurement_arguments()
    off = np.array([mag[0], 0.0])  # the magnet's loop without current: the base alone
    x = np.zeros(12)
    m = model.n_inputs
    y0 = phys.fast_measurement(x, np.zeros(m), src, coil, sens, off, work)
    G = np.empty((y0.shape[0], m))
    for i in range(m):
        u = np.zeros(m)
        u[i] = 1.0
        G[:, i] = phys.fast_measurement(x, u, src, coil, sens, off, work) - y0
    return np.ascontiguousarray(y0), np.ascontiguousarray(G)


@njit(cache=True)
def embed(dx, x_eq, reduced):  # pragma: no cover - jitted
    """Full 12-state from a reduced deviation ``dx`` (its first ``len(reduced)`` entries).

    Parameters
    ----------
    dx : ndarray, shape (n,)
        Reduced deviation (entries beyond ``len(reduced)``, such as biases, are ignored).
    x_eq : ndarray, shape (12,)
        Equilibrium.
    reduced : ndarray of int, shape (10,)
        Indices of the reduced states in the 12-state.
    """
    x = x_eq.copy()
    for i in range(reduced.shape[0]):
        x[reduced[i]] += dx[i]
    return x


@njit(cache=True, error_model='numpy')
def _loop_point(dx, dy, z, a, current):  # pragma: no cover - jitted
    """Field (Bx, By, Bz) of a loop at the origin (axis z) at one point, T.

    ``physics.loop.loop_batch`` for a single pair, without its work arrays
    (the same formulas and AGM sweeps, so the same numbers to round-off).
    """
    r = math.sqrt(dx * dx + dy * dy)
    iv = 1.0 / ((a + r) * (a + r) + z * z)
    dd = (a - r) * (a - r) + z * z
    m = 4.0 * a * r * iv
    b = math.sqrt(dd * iv)
    an = 0.5 * (1.0 + b)
    bn = math.sqrt(b)
    dn = 1.0 / (2.0 * (1.0 + b))
    u_sum = dn * dn
    weight = 1.0
    sweeps = 0
    while an - bn > 1e-14 * an and sweeps < AGM_ITERATIONS:
        weight *= 2.0
        a_next = 0.5 * (an + bn)
        bn = math.sqrt(an * bn)
        an = a_next
        dn = m * dn * dn / (4.0 * a_next)
        u_sum += weight * dn * dn
        sweeps += 1
    k = math.pi / (an + bn)
    k_minus_e = k * m * (0.5 + m * u_sum)
    e = k - k_minus_e
    pref = MU0 / (2.0 * math.pi) * current * math.sqrt(iv)
    inv_d = 1.0 / dd
    brho_over_rho = -pref * z * 8.0 * a * a * k * ((2.0 - m) * u_sum - 0.5) * iv * inv_d
    bz = pref * (k_minus_e + 2.0 * a * (a - r) * e * inv_d)
    return brho_over_rho * dx, brho_over_rho * dy, bz


@njit(cache=True, error_model='numpy')
def magnet_reading(x12, u, y0, G, sens, mag, own_src, own_coil, work):  # pragma: no cover
    """h(x, u): readings of the base (``y0 + G u``) plus the levitating magnet's field, T.

    Parameters
    ----------
    x12 : ndarray, shape (12,)
        State.
    u : ndarray, shape (n_s,)
        Coil currents, A.
    y0, G : ndarray
        :func:`base_reading`.
    sens, mag : ndarray
        The model's sensor and magnet arguments (``measurement_arguments``).
    own_src : ndarray, shape (1, 6)
        The magnet's loop as a source at the origin: radius ``mag[0]``, current ``mag[1]``.
    own_coil : ndarray of int64, shape (1,)
        -1 (no coil feeds it).
    work : ndarray
        Scratch space of the model (unused: the magnet's loop is evaluated point by
        point, :func:`_loop_point`).
    """
    r = phys.rotation_matrix(x12[3], x12[4], x12[5])
    k = sens.shape[0]
    m = u.shape[0]
    y = y0.copy()
    for i in range(y.shape[0]):
        acc = 0.0
        for j in range(m):
            acc += G[i, j] * u[j]
        y[i] += acc
    radius, current = own_src[0, 3], own_src[0, 4]
    for s in range(k):
        wx = sens[s, 0] - x12[0]
        wy = sens[s, 1] - x12[1]
        wz = sens[s, 2] - x12[2]
        lx = r[0, 0] * wx + r[1, 0] * wy + r[2, 0] * wz
        ly = r[0, 1] * wx + r[1, 1] * wy + r[2, 1] * wz
        lz = r[0, 2] * wx + r[1, 2] * wy + r[2, 2] * wz
        bx, by, bz = _loop_point(lx, ly, lz, radius, current)
        t0 = r[0, 0] * bx + r[0, 1] * by + r[0, 2] * bz
        t1 = r[1, 0] * bx + r[1, 1] * by + r[1, 2] * bz
        t2 = r[2, 0] * bx + r[2, 1] * by + r[2, 2] * bz
        for a in range(3):
            reading = sens[s, 3 + a] * t0 + sens[s, 6 + a] * t1 + sens[s, 9 + a] * t2
            y[3 * s + a] += sens[s, 12 + a] * reading
    return y


@njit(cache=True)
def filter_measurement(dx, u, x_eq, reduced, y0, G, sens, mag, own_src, own_coil, work):
    """Predicted reading of a filter state ``dx`` (reduced deviation + biases), T, (3 k,).

    Parameters
    ----------
    dx : ndarray, shape (n,)
        Reduced deviation, then (optionally) one bias per reading.
    u : ndarray, shape (n_s,)
        Coil currents, A.
    x_eq : ndarray, shape (12,)
    reduced : ndarray of int, shape (10,)
    y0, G, sens, mag, own_src, own_coil, work
        As :func:`magnet_reading`.
    """  # pragma: no cover - jitted
    n_r = reduced.shape[0]
    y = magnet_reading(embed(dx, x_eq, reduced), u, y0, G, sens, mag, own_src, own_coil, work)
    if dx.shape[0] > n_r:
        for i in range(y.shape[0]):
            y[i] += dx[n_r + i]
    return y


@njit(cache=True)
def measurement_jacobian(
    dx, u, x_eq, reduced, step, y0, G, sens, mag, own_src, own_coil, work
):  # pragma: no cover - jitted
    """Return h at ``dx`` and its Jacobian by central differences: (3 k,), (3 k, n).

    Parameters
    ----------
    dx, u, x_eq, reduced
        As :func:`filter_measurement`.
    step : float
        Finite-difference step.
    y0, G, sens, mag, own_src, own_coil, work
        As :func:`magnet_reading`.
    """
    n_r = reduced.shape[0]
    n = dx.shape[0]
    x12 = embed(dx, x_eq, reduced)
    y = magnet_reading(x12, u, y0, G, sens, mag, own_src, own_coil, work)
    m = y.shape[0]
    H = np.zeros((m, n))
    for j in range(n_r):
        if reduced[j] >= 6:
            continue  # h depends on the pose only: a velocity's column is zero
        xp = x12.copy()
        xm = x12.copy()
        xp[reduced[j]] += step
        xm[reduced[j]] -= step
        yp = magnet_reading(xp, u, y0, G, sens, mag, own_src, own_coil, work)
        ym = magnet_reading(xm, u, y0, G, sens, mag, own_src, own_coil, work)
        for i in range(m):
            H[i, j] = (yp[i] - ym[i]) / (2.0 * step)
    if n > n_r:
        for i in range(m):
            y[i] += dx[n_r + i]
            H[i, n_r + i] = 1.0
    return y, H


@njit(cache=True)
def series_transition(A, dt):  # pragma: no cover - jitted
    """``exp(A dt)`` and ``dt phi1(A dt)`` by their series to ``(A dt)^3``: (r, r), (r, r).

    Parameters
    ----------
    A : ndarray, shape (r, r)
        Jacobian of the reduced dynamics, 1/s.
    dt : float
        s.
    """
    r = A.shape[0]
    Z = A * dt
    Z2 = _mm(Z, Z)  # plain loops: a BLAS call costs more than a 10x10 product
    Z3 = _mm(Z2, Z)
    F = np.eye(r) + Z + 0.5 * Z2 + Z3 / 6.0
    M = (np.eye(r) + 0.5 * Z + Z2 / 6.0 + Z3 / 24.0) * dt
    return F, M
