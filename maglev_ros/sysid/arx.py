"""ARX estimation by linear least squares (the toolbox's ``arx``).

Each output row ``i`` of ``A(q) y = B(q) u + e`` is a linear regression
``y_i(t) = phi_i(t)^T theta_i + e_i(t)`` solved independently (rows share no
parameters).

Default solver (``method='auto'``): the normal equations
``(Phi^T Phi) theta = Phi^T y`` are built directly from lagged correlations of
the signals (:mod:`maglev_ros.sysid.correlation`: ~p dot products, no N x p
regression matrix) and solved by Cholesky.  Why: for the lab's 25,000-sample
data this is several times faster than forming ``Phi`` and factoring it.  The
rounding error of normal equations grows like ``cond(Phi^T Phi) * eps``;
below ``cond = 1e10`` that is < 1e-6 relative, far below the statistical
error of any estimate from noisy data.  Above it (high-order models of slow,
oversampled systems such as na=7 nb=9 at 5 kHz reach 1e9-1e12) one step of
iterative refinement with the true residual - obtained by FIR filtering,
still without ``Phi`` - restores QR-level accuracy up to ``cond = 1e13``.
Beyond that the solver forms ``Phi`` and uses a Householder QR of
``[Phi, y]`` (LAPACK ``geqrf``, R factor only).  ``method='normal'`` forms
``Phi`` and solves the normal equations with one step of iterative
refinement; ``method='qr'`` always uses QR.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla

from .correlation import block_sizes, lag_gram
from .dataset import IdData, as_experiments
from .model import PolyModel
from .orders import Orders, make_orders
from .regression import arx_regressors, check_data, finish_model, fir_add, join, stack_rows

__all__ = ['arx', 'least_squares']

COND_LIMIT = 1e12
CORRELATION_COND_LIMIT = 1e13
REFINE_ABOVE = 1e10


def least_squares(
    Phi: np.ndarray, Y: np.ndarray, method: str = 'auto'
) -> tuple[np.ndarray, np.ndarray, str]:
    """Solve ``min ||Y - Phi theta||`` and return ``(Phi^T Phi)^-1`` for the covariance.

    Parameters
    ----------
    Phi : ndarray, shape (N, p)
        Regression matrix.
    Y : ndarray, shape (N,)
        Targets.
    method : {'auto', 'normal', 'qr'}
        ``'normal'``: Cholesky of the normal equations plus one refinement
        step; ``'qr'``: QR of ``[Phi, Y]``; ``'auto'``: normal equations unless
        ``cond(Phi^T Phi) > 1e12``.

    Returns
    -------
    theta : ndarray, shape (p,)
        Estimate.
    Rinv : ndarray, shape (p, p)
        ``(Phi^T Phi)^-1``.
    used : str
        The method actually used.
    """
    if method not in ('auto', 'normal', 'qr'):
        raise ValueError(f"method must be 'auto', 'normal' or 'qr', got {method!r}")
    p = Phi.shape[1]
    if p == 0:
        return np.zeros(0), np.zeros((0, 0)), 'none'
    if method != 'qr':
        R = Phi.T @ Phi
        if method == 'normal' or np.linalg.cond(R) < COND_LIMIT:
            try:
                factor = sla.cho_factor(R, check_finite=False)
            except np.linalg.LinAlgError:
                factor = None
            if factor is not None:
                theta = sla.cho_solve(factor, Phi.T @ Y, check_finite=False)
                theta += sla.cho_solve(factor, Phi.T @ (Y - Phi @ theta), check_finite=False)
                Rinv = sla.cho_solve(factor, np.eye(p), check_finite=False)
                return theta, Rinv, 'normal equations (Cholesky, refined)'
    raw = sla.qr(np.column_stack([Phi, Y]), mode='raw', check_finite=False)[0][0]
    Rfull = np.triu(raw[: p + 1, : p + 1])  # R factor of [Phi, Y] (Householder, no Q)
    Rq = Rfull[:p, :p]
    theta = sla.solve_triangular(Rq, Rfull[:p, p], check_finite=False)
    Rq_inv = sla.solve_triangular(Rq, np.eye(p), check_finite=False)
    return theta, Rq_inv @ Rq_inv.T, 'QR'


def arx(
    data: IdData | Sequence[IdData], na: object, nb: object, nk: object = 1, method: str = 'auto'
) -> PolyModel:
    """Estimate an ARX model ``A(q) y(t) = B(q) u(t - nk) + e(t)``.

    Parameters
    ----------
    data : IdData or sequence of IdData
        Estimation data (several experiments are stacked).
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and input delays in samples.
    method : {'auto', 'normal', 'qr'}
        ``'auto'``: normal equations from lagged correlations
        (:mod:`~.correlation`, no regression matrix is formed), QR if they
        are ill-conditioned; ``'normal'``/``'qr'``: see :func:`least_squares`.

    Returns
    -------
    PolyModel
        Model with parameter covariance ``lambda (Phi^T Phi)^-1`` per output.

    Raises
    ------
    OrderError
        For inconsistent order matrices.
    ValueError
        For fewer samples than parameters.
    """
    experiments = as_experiments(data)
    first = experiments[0]
    orders = make_orders(first.ny, first.nu, na=na, nb=nb, nk=nk)
    theta, cov, used = arx_rows(experiments, orders, method)
    return finish_model('arx', orders, theta, cov, experiments, f'ARX, {used}')


def arx_rows(
    experiments: Sequence[IdData], orders: Orders, method: str = 'auto', refine: bool = True
) -> tuple[np.ndarray, np.ndarray, str]:
    """Least-squares estimate of the ``A``/``B`` parameters of every output row.

    Parameters
    ----------
    experiments : sequence of IdData
        Estimation data.
    orders : Orders
        Orders (``nc``, ``nd``, ``nf`` must be zero).
    method : str
        Solver, see :func:`least_squares`.
    refine : bool
        Allow the refinement step of :func:`correlation_solve` (off for
        intermediate estimates whose last digits do not matter).

    Returns
    -------
    theta : ndarray, shape (n_params,)
        Stacked row estimates.
    covariance : ndarray, shape (n_params, n_params)
        Block-diagonal parameter covariance.
    used : str
        Solver used (of the last row).
    """
    check_data(experiments, orders)
    thetas, covs = [], []
    used = ''
    signals = [signal_matrix(d) for d in experiments] if method == 'auto' else []
    for i in range(orders.ny):
        start = orders.row_start(i)
        solved = None
        if method == 'auto':
            solved = correlation_solve(signals, row_blocks(orders, i), i, start, refine)
        if solved is not None:
            theta, Rinv, lam = solved
            used = 'normal equations from lagged correlations (Cholesky)'
        else:
            Phi = stack_rows([arx_regressors(d.y, d.u, orders, i, start) for d in experiments])
            Y = join([d.y[start:, i] for d in experiments])
            theta, Rinv, used = least_squares(Phi, Y, method)
            resid = Y - Phi @ theta
            lam = float(resid @ resid) / max(1, len(Y) - len(theta))
        thetas.append(theta)
        covs.append(lam * Rinv)
    return np.concatenate(thetas), sla.block_diag(*covs), used


def signal_matrix(data: IdData, *extra: np.ndarray) -> np.ndarray:
    """Stack ``y`` (N, ny), ``u`` (N, nu) and extra (N, k) signals as rows, (ny+nu+k, N).

    Parameters
    ----------
    data : IdData
        The data set.
    *extra : ndarray, shape (N, k)
        Further signals.
    """
    return np.ascontiguousarray(np.vstack([data.y.T, data.u.T, *[e.T for e in extra]]))


def row_blocks(
    orders: Orders, i: int, out_base: int = 0, in_base: int | None = None
) -> np.ndarray:
    """Regressor blocks of output row ``i`` for :func:`~.correlation.lag_gram`.

    Parameters
    ----------
    orders : Orders
        Model orders.
    i : int
        Output row.
    out_base, in_base : int
        Row of the first output / input signal in the signal matrix (default
        ``0`` and ``ny``; instruments replace the outputs with ``out_base``).

    Returns
    -------
    ndarray, shape (n_blocks, 4), int
        ``(signal, first lag, count, sign)`` rows in the parameter layout order.
    """
    in_base = orders.ny if in_base is None else in_base
    rows = [
        (out_base + j, 1, int(orders.na[i, j]), -1) for j in range(orders.ny) if orders.na[i, j]
    ]
    rows += [
        (in_base + j, int(orders.nk[i, j]), int(orders.nb[i, j]), 1)
        for j in range(orders.nu)
        if orders.nb[i, j]
    ]
    return np.array(rows, dtype=np.int64).reshape(-1, 4)


def correlation_solve(
    signals: Sequence[np.ndarray], blocks: np.ndarray, target: int, start: int, refine: bool = True
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Least squares of ``signal[target](t)`` on lagged regressors from correlations.

    Parameters
    ----------
    signals : sequence of ndarray, shape (n_signals, N_e)
        Signal matrices, one per experiment.
    blocks : ndarray, shape (n_blocks, 4)
        Regressor blocks.
    target : int
        Row of the regressed signal (at lag 0).
    start : int
        First time index.
    refine : bool
        Allow the iterative-refinement step (needed for full accuracy above
        ``cond = 1e10`` or with a near-zero residual).

    Returns
    -------
    tuple or None
        ``(theta, (Phi^T Phi)^-1, lambda)`` with the unbiased residual variance,
        or None if ``cond(Phi^T Phi) > 1e13`` (the caller then uses QR).  Above
        ``cond = 1e10`` one step of iterative refinement with the true residual
        (computed by FIR filtering) restores QR-level accuracy.
    """
    tgt = np.array([[target, 0, 1, 1]], dtype=np.int64)
    p = block_sizes(blocks)
    both = np.vstack([np.asarray(blocks, dtype=np.int64).reshape(-1, 4), tgt])
    G = np.zeros((p + 1, p + 1))  # [Phi, y]^T [Phi, y] in one symmetric product
    M = 0
    for S in signals:
        G += lag_gram(S, both, both, start)
        M += S.shape[1] - start
    R, r, yy = G[:p, :p], G[:p, p].copy(), float(G[p, p])
    if p == 0:
        return np.zeros(0), np.zeros((0, 0)), yy / max(M, 1)
    cond = np.linalg.cond(R)
    if not cond < CORRELATION_COND_LIMIT:
        return None
    try:
        factor = sla.cho_factor(R, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    theta = sla.cho_solve(factor, r, check_finite=False)
    if cond < REFINE_ABOVE or not refine:
        sse = yy - 2.0 * theta @ r + theta @ R @ theta
    else:
        sse = -1.0
    if not sse > 1e-9 * yy:
        # Ill-conditioned, or too little residual for the quadratic form: one step of
        # iterative refinement with the true residual (still without forming Phi).
        residuals = [_residual(S, blocks, target, theta, start) for S in signals]
        g = np.zeros(p)
        e_blk = np.array([[0, 0, 1, 1]], dtype=np.int64)
        for S, res in zip(signals, residuals, strict=True):
            full = np.zeros(S.shape[1])
            full[start:] = res
            g += lag_gram(np.vstack([S, full]), blocks, e_blk + [S.shape[0], 0, 0, 0], start)[:, 0]
        theta = theta + sla.cho_solve(factor, g, check_finite=False)
        sse = float(
            sum(
                float(x @ x) for x in (_residual(S, blocks, target, theta, start) for S in signals)
            )
        )
    Rinv = sla.cho_solve(factor, np.eye(p), check_finite=False)
    return theta, Rinv, sse / max(1, M - p)


def _residual(
    S: np.ndarray, blocks: np.ndarray, target: int, theta: np.ndarray, start: int
) -> np.ndarray:
    """``signal[target](t) - phi(t)^T theta`` for ``t >= start`` by FIR filtering, (N - start,)."""
    fitted = np.zeros(S.shape[1])
    pos = 0
    for sig, first, count, sign in blocks:
        h = np.zeros(first + count)
        h[first:] = sign * theta[pos : pos + count]
        pos += count
        fir_add(h, S[sig], fitted)  # compiled FIR (regression.fir_add)
    return S[target, start:] - fitted[start:]
