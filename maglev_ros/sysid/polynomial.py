"""Polynomial arrays, parameter packing and the innovations state-space realization.

Polynomials in ``q^-1`` are stored padded in arrays indexed ``[..., lag]``:
``A`` (ny, ny, 1 + max na), ``B`` (ny, nu, max(nk + nb)), ``C`` and ``D``
(ny, 1 + max nc/nd) and ``F`` (ny, nu, 1 + max nf).  ``A[i, i, 0] = C[i, 0] =
D[i, 0] = F[i, j, 0] = 1``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .orders import Orders

__all__ = ['Polynomials', 'equivalent_armax', 'innovations_form', 'pack', 'unpack']

Polynomials = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def unpack(orders: Orders, theta: np.ndarray) -> Polynomials:
    """Turn a parameter vector into padded polynomial arrays.

    Parameters
    ----------
    orders : Orders
        Model orders.
    theta : ndarray, shape (n_params,)
        Parameters in the layout of :mod:`maglev_ros.sysid.orders`.

    Returns
    -------
    tuple of ndarray
        ``(A, B, C, D, F)`` padded arrays.
    """
    o = orders
    ny, nu = o.ny, o.nu
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (o.n_params,):
        raise ValueError(f'theta must have shape ({o.n_params},), got {theta.shape}')
    A = np.zeros((ny, ny, 1 + int(o.na.max(initial=0))))
    B = np.zeros((ny, nu, max(1, int((o.nk + o.nb).max(initial=0)))))
    C = np.zeros((ny, 1 + int(o.nc.max(initial=0))))
    D = np.zeros((ny, 1 + int(o.nd.max(initial=0))))
    F = np.zeros((ny, nu, 1 + int(o.nf.max(initial=0))))
    A[np.arange(ny), np.arange(ny), 0] = 1.0
    C[:, 0] = D[:, 0] = 1.0
    F[:, :, 0] = 1.0
    pos = 0
    for i in range(ny):
        for j in range(ny):
            n = o.na[i, j]
            A[i, j, 1 : n + 1] = theta[pos : pos + n]
            pos += n
        for j in range(nu):
            n, k = o.nb[i, j], o.nk[i, j]
            B[i, j, k : k + n] = theta[pos : pos + n]
            pos += n
        C[i, 1 : o.nc[i] + 1] = theta[pos : pos + o.nc[i]]
        pos += o.nc[i]
        D[i, 1 : o.nd[i] + 1] = theta[pos : pos + o.nd[i]]
        pos += o.nd[i]
        for j in range(nu):
            n = o.nf[i, j]
            F[i, j, 1 : n + 1] = theta[pos : pos + n]
            pos += n
    return A, B, C, D, F


def pack(orders: Orders, polys: Polynomials) -> np.ndarray:
    """Inverse of :func:`unpack`: collect the free coefficients into a vector.

    Parameters
    ----------
    orders : Orders
        Model orders.
    polys : tuple of ndarray
        ``(A, B, C, D, F)`` padded arrays.

    Returns
    -------
    ndarray, shape (n_params,)
        Parameter vector.
    """
    A, B, C, D, F = polys
    o = orders
    out: list[np.ndarray] = []
    for i in range(o.ny):
        out += [A[i, j, 1 : o.na[i, j] + 1] for j in range(o.ny)]
        out += [B[i, j, o.nk[i, j] : o.nk[i, j] + o.nb[i, j]] for j in range(o.nu)]
        out += [C[i, 1 : o.nc[i] + 1], D[i, 1 : o.nd[i] + 1]]
        out += [F[i, j, 1 : o.nf[i, j] + 1] for j in range(o.nu)]
    return np.concatenate(out) if out else np.zeros(0)


def _pad(p: np.ndarray, n: int) -> np.ndarray:
    out = np.zeros(n)
    out[: len(p)] = p
    return out


def equivalent_armax(
    polys: Polynomials, noise: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rewrite the model as a matrix ARMAX ``Ae(q) y = Be(q) u + Ce(q) e``.

    ``F`` and ``D`` (only allowed with a diagonal ``A``) are moved into common
    denominators row by row: ``Ae_i = A_ii D_i prod_j F_ij``.

    Parameters
    ----------
    polys : tuple of ndarray
        ``(A, B, C, D, F)`` padded arrays.
    noise : bool
        Include ``D`` in the denominators (False gives the deterministic part).

    Returns
    -------
    tuple of ndarray
        ``Ae`` (ny, ny, n+1), ``Be`` (ny, nu, n+1), ``Ce`` (ny, n+1), all with the
        same length ``n + 1``.
    """
    A, B, C, D, F = polys
    ny, nu = B.shape[0], B.shape[1]
    trivial_f = F.shape[2] == 1 and (not noise or D.shape[1] == 1)
    if trivial_f:
        n = max(A.shape[2], B.shape[2], C.shape[1]) - 1
        Ae = np.zeros((ny, ny, n + 1))
        Ae[:, :, : A.shape[2]] = A
        Be = np.zeros((ny, nu, n + 1))
        Be[:, :, : B.shape[2]] = B
        Ce = np.zeros((ny, n + 1))
        Ce[:, : C.shape[1]] = C
        return Ae, Be, Ce
    rows_a, rows_b, rows_c = [], [], []
    for i in range(ny):
        fprod = np.ones(1)
        for j in range(nu):
            fprod = np.convolve(fprod, F[i, j])
        d = D[i] if noise else np.ones(1)
        rows_a.append(np.convolve(np.convolve(A[i, i], d), fprod))
        bs = []
        for j in range(nu):
            others = np.ones(1)
            for m in range(nu):
                if m != j:
                    others = np.convolve(others, F[i, m])
            bs.append(np.convolve(np.convolve(B[i, j], d), others))
        rows_b.append(bs)
        rows_c.append(np.convolve(C[i], fprod))
    n = (
        max(
            [len(a) for a in rows_a]
            + [len(b) for r in rows_b for b in r]
            + [len(c) for c in rows_c]
        )
        - 1
    )
    Ae = np.zeros((ny, ny, n + 1))
    Be = np.zeros((ny, nu, n + 1))
    Ce = np.zeros((ny, n + 1))
    for i in range(ny):
        Ae[i, i] = _pad(rows_a[i], n + 1)
        Ce[i] = _pad(rows_c[i], n + 1)
        for j in range(nu):
            Be[i, j] = _pad(rows_b[i][j], n + 1)
    return Ae, Be, Ce


def innovations_form(
    polys: Polynomials, noise: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Block observer-canonical innovations form ``x+ = Ax + Bu + Ke``, ``y = Cx + Du + e``.

    Parameters
    ----------
    polys : tuple of ndarray
        ``(A, B, C, D, F)`` padded arrays.
    noise : bool
        Include the noise model (False: deterministic part only, ``K`` still
        returned for the noise-free structure).

    Returns
    -------
    tuple of ndarray
        ``A`` (n, n), ``B`` (n, nu), ``C`` (ny, n), ``D`` (ny, nu), ``K`` (n, ny)
        with ``n = ny * degree``.  The realization need not be minimal.
    """
    Ae, Be, Ce = equivalent_armax(polys, noise)
    ny, nu, n1 = Be.shape
    deg = n1 - 1
    nx = ny * deg
    Ass = np.zeros((nx, nx))
    Bss = np.zeros((nx, nu))
    Kss = np.zeros((nx, ny))
    B0 = Be[:, :, 0]
    for k in range(1, deg + 1):
        rows = slice((k - 1) * ny, k * ny)
        Ak = Ae[:, :, k]
        Ass[rows, 0:ny] = -Ak
        if k < deg:
            Ass[rows, k * ny : (k + 1) * ny] = np.eye(ny)
        Bss[rows] = Be[:, :, k] - Ak @ B0
        Kss[rows] = np.diag(Ce[:, k]) - Ak
    Css = np.zeros((ny, nx))
    if deg:
        Css[:, :ny] = np.eye(ny)
    return Ass, Bss, Css, B0.copy(), Kss


@njit(cache=True)
def simulate_ss(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, x0: np.ndarray, u: np.ndarray
) -> np.ndarray:  # pragma: no cover - numba
    """Simulate ``x+ = Ax + Bu``, ``y = Cx + Du``; ``u`` (N, nu) -> ``y`` (N, ny).

    Parameters
    ----------
    A : ndarray, shape (n, n)
        State matrix.
    B : ndarray, shape (n, nu)
        Input matrix.
    C : ndarray, shape (ny, n)
        Output matrix.
    D : ndarray, shape (ny, nu)
        Feedthrough.
    x0 : ndarray, shape (n,)
        Initial state.
    u : ndarray, shape (N, nu)
        Inputs.
    """
    N, nu = u.shape
    ny, n = C.shape
    y = np.empty((N, ny))
    x = x0.copy()
    xn = np.empty(n)
    for t in range(N):
        for i in range(ny):
            acc = 0.0
            for k in range(n):
                acc += C[i, k] * x[k]
            for k in range(nu):
                acc += D[i, k] * u[t, k]
            y[t, i] = acc
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += A[i, k] * x[k]
            for k in range(nu):
                acc += B[i, k] * u[t, k]
            xn[i] = acc
        x, xn = xn, x
    return y


@njit(cache=True)
def predictor_errors(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    D: np.ndarray,
    K: np.ndarray,
    x0: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
) -> np.ndarray:  # pragma: no cover - numba
    """One-step prediction errors of the innovations form (Kalman predictor), (N, ny).

    Parameters
    ----------
    A : ndarray, shape (n, n)
        State matrix.
    B : ndarray, shape (n, nu)
        Input matrix.
    C : ndarray, shape (ny, n)
        Output matrix.
    D : ndarray, shape (ny, nu)
        Feedthrough.
    K : ndarray, shape (n, ny)
        Kalman (innovations) gain.
    x0 : ndarray, shape (n,)
        Initial state.
    u : ndarray, shape (N, nu)
        Inputs.
    y : ndarray, shape (N, ny)
        Outputs.
    """
    N, nu = u.shape
    ny, n = C.shape
    e = np.empty((N, ny))
    x = x0.copy()
    xn = np.empty(n)
    for t in range(N):
        for i in range(ny):
            acc = y[t, i]
            for k in range(n):
                acc -= C[i, k] * x[k]
            for k in range(nu):
                acc -= D[i, k] * u[t, k]
            e[t, i] = acc
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += A[i, k] * x[k]
            for k in range(nu):
                acc += B[i, k] * u[t, k]
            for k in range(ny):
                acc += K[i, k] * e[t, k]
            xn[i] = acc
        x, xn = xn, x
    return e


@njit(cache=True)
def free_response(A: np.ndarray, C: np.ndarray, N: int) -> np.ndarray:  # pragma: no cover
    """Stacked ``C A^t`` for t = 0..N-1, shape (N, ny, n).

    Parameters
    ----------
    A : ndarray, shape (n, n)
        State matrix.
    C : ndarray, shape (ny, n)
        Output matrix.
    N : int
        Number of samples.
    """
    ny, n = C.shape
    out = np.empty((N, ny, n))
    M = C.copy()
    for t in range(N):
        out[t] = M
        M = M @ A
    return out
