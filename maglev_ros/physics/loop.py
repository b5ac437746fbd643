"""Magnetic field of a circular current loop (the building block of every model).

The loop has radius ``a``, carries current ``I`` and sits at the origin with its
axis along z. In cylindrical coordinates (rho, phi, z), with
``S = (a + rho)^2 + z^2``, ``D = (a - rho)^2 + z^2`` and the elliptic parameter
``m = 4 a rho / S`` (so ``1 - m = D / S``)::

    B_rho = -(mu0 I / (2 pi sqrt(S))) (z / rho) [K(m) - (rho^2 + a^2 + z^2) / D E(m)]
    B_z   =  (mu0 I / (2 pi sqrt(S)))           [K(m) - (rho^2 - a^2 + z^2) / D E(m)]

which is the textbook form in ``maggy-model.md``. Evaluated literally, the
brackets cancel near the axis (``B_rho`` loses all digits as rho -> 0: the
published code sets it to zero below 1e-6 m, which breaks finite-difference
Jacobians). Here K and E come from the arithmetic-geometric mean, whose
sequence ``c_n`` also gives ``K - E`` and the rho-odd part of the bracket as
sums of positive terms. The result is free of cancellation, exact on the axis
(``B_rho / rho`` is computed directly, so Cartesian components need no angle),
analytic in rho, and needs no switch to a series near the axis. It agrees
with the textbook form (and with magpylib) to round-off elsewhere.

Derivation of the stable form (AGM: ``a_0 = 1, b_0 = sqrt(1 - m)``,
``c_{n+1} = c_n^2 / (4 a_{n+1})``, ``c_0^2 = m``)::

    K = pi / (2 a_inf),    K - E = K (m / 2 + m^2 U),    U = sum_{n>=1} 2^(n-1) (c_n / m)^2
    B_rho / rho = -(mu0 I / (2 pi sqrt(S))) z 8 a^2 K ((2 - m) U - 1/2) / (S D)
    B_z         =  (mu0 I / (2 pi sqrt(S))) [(K - E) + 2 a (a - rho) E / D]
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    'MU0',
    'AGM_ITERATIONS',
    'LOOP_WORK_ROWS',
    'as_points',
    'loop_batch',
    'loop_field_cylindrical',
    'loop_field',
]

MU0 = 4e-7 * math.pi  # vacuum permeability, N/A^2 (the model's value, not CODATA 2019)

#: Most AGM sweeps after the first step (done by hand). Convergence is quadratic:
#: sweeps stop once every pair has a_n and b_n equal to 1e-14 (then the limit is
#: (a_n + b_n) / 2 to ~1e-29); typically 3-4, 6 for points 1e-8 radii from the wire.
AGM_ITERATIONS = 12
#: Work rows needed by :func:`loop_batch`.
LOOP_WORK_ROWS = 9
# No fast-math: with 'reassoc' (or 'contract'/'arcp') LLVM's result depends on where a
# kernel is inlined, so a freshly compiled kernel and the one loaded from numba's cache
# differed in the last bits, and a closed loop's run after an install differed from the
# next one (the magnet's settled RMS 57/33 against 37/24 um). IEEE semantics make every
# run of the same seed give the same numbers.
FASTMATH: set[str] = set()


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def loop_batch(dx, dy, z, a, current, brho_over_rho, bz, work):  # pragma: no cover - jitted
    """Loop fields for a batch of (point, loop) pairs, vectorised (SIMD).

    Parameters
    ----------
    dx, dy, z : ndarray, shape (n,)
        Position of each point relative to its loop's centre, m.
    a : ndarray, shape (n,)
        Loop radii, m.
    current : ndarray, shape (n,)
        Loop currents, A.
    brho_over_rho : ndarray, shape (n,)
        Output: B_rho / rho, T/m (finite on the axis).
    bz : ndarray, shape (n,)
        Output: B_z, T.
    work : ndarray, shape (LOOP_WORK_ROWS, >= n)
        Scratch space.
    """
    n = dx.shape[0]
    an = work[0]
    bn = work[1]
    dn = work[2]
    u_sum = work[3]
    m = work[4]
    inv_s = work[5]
    d = work[6]
    rho = work[7]
    b_all = work[8]
    for i in range(n):
        r = math.sqrt(dx[i] * dx[i] + dy[i] * dy[i])
        rho[i] = r
        aa = a[i]
        zz = z[i]
        iv = 1.0 / ((aa + r) * (aa + r) + zz * zz)
        dd = (aa - r) * (aa - r) + zz * zz
        inv_s[i] = iv
        d[i] = dd
        m[i] = 4.0 * aa * r * iv
        b = math.sqrt(dd * iv)  # sqrt(1 - m) without subtraction
        b_all[i] = b
        an[i] = 0.5 * (1.0 + b)
        bn[i] = math.sqrt(b)
        q = 1.0 / (2.0 * (1.0 + b))  # c_1 / m
        dn[i] = q
        u_sum[i] = q * q
    # The pair with the smallest b converges slowest: count its sweeps once, then
    # run that many branch-free sweeps over the whole batch. (A separate loop: a
    # min-reduction inside the loop above would stop it from vectorising.)
    b_min = 1.0
    for i in range(n):
        if b_all[i] < b_min:
            b_min = b_all[i]
    sweeps = 0
    a_worst = 0.5 * (1.0 + b_min)
    b_worst = math.sqrt(b_min)
    while a_worst - b_worst > 1e-14 * a_worst and sweeps < AGM_ITERATIONS:
        a_worst, b_worst = 0.5 * (a_worst + b_worst), math.sqrt(a_worst * b_worst)
        sweeps += 1
    weight = 1.0
    for _ in range(sweeps):
        weight *= 2.0
        for i in range(n):
            a_next = 0.5 * (an[i] + bn[i])
            bn[i] = math.sqrt(an[i] * bn[i])
            an[i] = a_next
            q = m[i] * dn[i] * dn[i] / (4.0 * a_next)  # c_{k+1} / m
            dn[i] = q
            u_sum[i] += weight * q * q
    for i in range(n):
        aa = a[i]
        mm = m[i]
        uu = u_sum[i]
        iv = inv_s[i]
        inv_d = 1.0 / d[i]
        k = math.pi / (an[i] + bn[i])
        k_minus_e = k * mm * (0.5 + mm * uu)
        e = k - k_minus_e
        pref = MU0 / (2.0 * math.pi) * current[i] * math.sqrt(iv)
        brho_over_rho[i] = -pref * z[i] * 8.0 * aa * aa * k * ((2.0 - mm) * uu - 0.5) * iv * inv_d
        bz[i] = pref * (k_minus_e + 2.0 * aa * (aa - rho[i]) * e * inv_d)


def as_points(points) -> np.ndarray:
    """Validate observation points: a C-contiguous float array of shape (n, 3).

    Parameters
    ----------
    points : array_like, shape (n, 3) or (3,)
        Points, m.

    Raises
    ------
    ValueError
        When ``points`` is not of shape (n, 3) (a single point (3,) is accepted).
    """
    pts = np.ascontiguousarray(np.atleast_2d(np.asarray(points, dtype=float)))
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f'points must have shape (n, 3), got {np.shape(points)}')
    return pts


def loop_field_cylindrical(rho, z, radius: float, current: float):
    """Field of a loop in cylindrical components.

    Parameters
    ----------
    rho, z : array_like, same shape
        Radial distance from the axis (>= 0) and height above the loop plane, m.
    radius : float
        Loop radius, m.
    current : float
        Loop current, A (positive: counter-clockwise seen from +z).

    Returns
    -------
    b_rho, b_z : ndarray
        Field components, T, shaped like ``rho``.
    """
    rho_arr, z_arr = np.broadcast_arrays(np.asarray(rho, float), np.asarray(z, float))
    flat_rho = rho_arr.ravel()
    points = np.zeros((flat_rho.size, 3))
    points[:, 0] = flat_rho
    points[:, 2] = z_arr.ravel()
    field = loop_field(points, radius, current)
    return field[:, 0].reshape(rho_arr.shape), field[:, 2].reshape(rho_arr.shape)


def loop_field(points, radius: float, current: float) -> np.ndarray:
    """Field of a loop centred at the origin with its axis along z.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Observation points, m. Finite everywhere except on the wire itself.
    radius : float
        Loop radius, m.
    current : float
        Loop current, A (positive: counter-clockwise seen from +z).

    Returns
    -------
    ndarray, shape (n, 3)
        Flux density (Bx, By, Bz), T.
    """
    pts = as_points(points)
    n = pts.shape[0]
    brho_over_rho = np.empty(n)
    bz = np.empty(n)
    loop_batch(
        np.ascontiguousarray(pts[:, 0]),
        np.ascontiguousarray(pts[:, 1]),
        np.ascontiguousarray(pts[:, 2]),
        np.full(n, float(radius)),
        np.full(n, float(current)),
        brho_over_rho,
        bz,
        np.empty((LOOP_WORK_ROWS, n)),
    )
    return np.column_stack([brho_over_rho * pts[:, 0], brho_over_rho * pts[:, 1], bz])
