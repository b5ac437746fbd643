"""Field of a finite cylindrical current sheet (ideal solenoid, cylinder magnet).

A sheet of radius ``a`` and length ``L`` centred at the origin, axis z, carries
the azimuthal surface current density ``I / L`` (``I`` the total current). It is
the exact field of a uniformly magnetised cylinder with ``I = J L / mu0``.

With ``xi = z +- L/2``, ``alpha = a / sqrt(xi^2 + (rho + a)^2)``,
``beta = xi / sqrt(xi^2 + (rho + a)^2)``, ``gamma = (a - rho) / (a + rho)`` and the complementary
modulus ``kc^2 = (xi^2 + (a - rho)^2) / (xi^2 + (a + rho)^2)`` (Derby & Olbert,
Am. J. Phys. 78, 229 (2010))::

    B_rho = B0 [alpha+ C1(kc+) - alpha- C1(kc-)]
    B_z   = B0 a / (a + rho) [beta+ C2(kc+) - beta- C2(kc-)],   B0 = mu0 I / (pi L)

The generalised complete elliptic integrals are written with Carlson's
symmetric integrals (scipy.special ``elliprf``, ``elliprd``, ``elliprj``),
which include the third-kind integral ``Pi(1 - gamma^2, 1 - kc^2)``::

    C1 = R_F(0, kc^2, 1) - 2/3 R_D(0, kc^2, 1)                 (= K - 2 (K - E) / m)
    C2 = R_F(0, kc^2, 1) + gamma (1 - gamma) / 3 R_J(0, kc^2, 1, gamma^2)
                                                  (= K + gamma / (1 + gamma) (Pi - K))
"""

from __future__ import annotations

import numpy as np
from scipy.special import elliprd, elliprf, elliprj

from .loop import MU0, as_points

__all__ = ['sheet_field']


def _c1(kc2):
    return elliprf(0.0, kc2, 1.0) - 2.0 / 3.0 * elliprd(0.0, kc2, 1.0)


def _c2(kc2, gamma):
    with np.errstate(invalid='ignore', divide='ignore'):
        third = gamma * (1.0 - gamma) / 3.0 * elliprj(0.0, kc2, 1.0, gamma * gamma)
    # gamma == 0 (rho == a): the third-kind term's jumps of the two ends cancel
    # outside the sheet; on the sheet itself the field is not defined.
    third = np.where(gamma == 0.0, 0.0, third)
    return elliprf(0.0, kc2, 1.0) + third


def sheet_field(points, radius: float, length: float, current: float) -> np.ndarray:
    """Field of a cylindrical current sheet centred at the origin, axis z.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Observation points, m (not on the sheet itself).
    radius : float
        Sheet radius a, m.
    length : float
        Sheet length L, m.
    current : float
        Total azimuthal current I, A (surface density I / L; for a magnet with
        polarisation J, I = J L / mu0).

    Returns
    -------
    ndarray, shape (n, 3)
        Flux density (Bx, By, Bz), T.
    """
    pts = as_points(points)
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    rho = np.hypot(x, y)
    a = float(radius)
    b0 = MU0 * current / (np.pi * length)
    gamma = (a - rho) / (a + rho)
    b_rho = np.zeros_like(rho)
    b_z = np.zeros_like(rho)
    for sign in (1.0, -1.0):
        xi = z + sign * length / 2.0
        far2 = xi * xi + (a + rho) ** 2
        inv = 1.0 / np.sqrt(far2)
        kc2 = (xi * xi + (a - rho) ** 2) / far2
        b_rho += sign * a * inv * _c1(kc2)  # alpha = a * inv
        b_z += sign * xi * inv * _c2(kc2, gamma)  # beta = xi * inv
    b_rho *= b0
    b_z *= b0 * a / (a + rho)
    out = np.empty_like(pts)
    with np.errstate(invalid='ignore', divide='ignore'):
        cos_phi = np.where(rho > 0, x / rho, 0.0)
        sin_phi = np.where(rho > 0, y / rho, 0.0)
    out[:, 0] = b_rho * cos_phi
    out[:, 1] = b_rho * sin_phi
    out[:, 2] = b_z
    return out
