"""ARMAX estimation by the prediction-error method (the toolbox's ``armax``).

Model ``A(q) y(t) = B(q) u(t - nk) + C(q) e(t)`` with a diagonal ``C`` for MIMO
data (``nc`` has one order per output).  Output rows share no parameters, so
each row is a separate minimization of ``sum e_i(t)^2``:

* prediction error ``e_i = (A_i y - B_i u) / C_i`` with zero past before the
  first sample (as the model's one-step predictor), summed from the first
  sample where all regressors exist;
* gradient ``psi = [phi_AB, e(t-1) .. e(t-nc)] / C_i``: ``y``, ``u`` and ``e`` are
  filtered by ``1/C_i`` once per iteration and ``psi^T psi``, ``psi^T e`` are
  formed from their lagged correlations (:mod:`~.correlation`), never ``psi``;
* start: a high-order ARX row (normal equations from correlations) gives
  innovation estimates, then a linear regression on ``[phi_AB, e_hat lags]``
  (Hannan-Rissanen), ``C`` reflected to minimum phase;
* Levenberg-Marquardt iterations (:mod:`maglev_ros.sysid.pem`) with ``C`` kept
  minimum phase by root reflection.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.linalg as sla

from .arx import correlation_solve, least_squares, row_blocks, signal_matrix
from .correlation import block_sizes, lag_gram
from .dataset import IdData, as_experiments
from .filters import inverse_filter
from .model import PolyModel
from .orders import Orders, make_orders
from .pem import levenberg_marquardt, stabilize
from .regression import arx_regressors, check_data, equation_errors, finish_model, join, stack_rows

__all__ = ['armax']

DEFAULT_TOL = 0.1  # relative loss decrease x samples that ends the iterations (see armax)


def _row_equation_error(d: IdData, orders: Orders, i: int, theta_ab: np.ndarray) -> np.ndarray:
    """``A_i y - B_i u`` of one row for all samples (FIR filters, zero past), shape (N,)."""
    return equation_errors(d.y, d.u, orders, theta_ab, rows=[i])[0]


def _initial_innovations(
    experiments: Sequence[IdData], orders: Orders, i: int, extra: int
) -> list[np.ndarray] | None:
    """Residuals of a high-order ARX row (zeros before its start), one array per experiment."""
    na = orders.na.copy()
    nb = orders.nb.copy()
    na[i] = np.where(na[i] > 0, na[i] + extra, 0)
    na[i, i] = orders.na[i, i] + extra
    nb[i] = np.where(nb[i] > 0, nb[i] + extra, 0)
    hi = Orders(na, nb, orders.nk, orders.nc * 0, orders.nd * 0, orders.nf * 0)
    start = hi.row_start(i)
    solved = correlation_solve(
        [signal_matrix(d) for d in experiments], row_blocks(hi, i), i, start
    )
    if solved is None:
        return None
    out = []
    for d in experiments:
        e = _row_equation_error(d, hi, i, solved[0])
        e[:start] = 0.0
        out.append(e)
    return out


def _armax_row(
    experiments: Sequence[IdData],
    orders: Orders,
    i: int,
    max_iter: int,
    tol: float | None,
    progress: Callable[[int, float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, int, bool]:
    nc = int(orders.nc[i])
    start = max(orders.row_start(i), nc)
    reg = row_blocks(orders, i)
    n_ab = block_sizes(reg)
    if nc == 0:
        solved = correlation_solve([signal_matrix(d) for d in experiments], reg, i, start)
        if solved is not None:
            return solved[0], solved[2] * solved[1], 0, True
    if nc == 0:
        Phi = stack_rows([arx_regressors(d.y, d.u, orders, i, start) for d in experiments])
        Y = join([d.y[start:, i] for d in experiments])
        theta, Rinv, _ = least_squares(Phi, Y)
        r = Y - Phi @ theta
        return theta, float(r @ r) / max(1, len(Y) - len(theta)) * Rinv, 0, True
    usable = min(d.N for d in experiments) - start
    extra = int(min(max(10, 3 * nc), max(1, usable // (8 * (orders.ny + orders.nu)))))
    ehat = _initial_innovations(experiments, orders, i, extra)
    e_row = orders.ny + orders.nu  # row of the innovation signal in the signal matrices
    blocks = np.vstack([reg, [[e_row, 1, nc, 1]]]).astype(np.int64)
    theta0 = None
    if ehat is not None:
        first = correlation_solve(
            [signal_matrix(d, e[:, None]) for d, e in zip(experiments, ehat, strict=True)],
            blocks,
            i,
            start,
        )
        theta0 = None if first is None else first[0]
    if theta0 is None:  # ill-conditioned start: plain ARX with C = 1
        Phi = stack_rows([arx_regressors(d.y, d.u, orders, i, start) for d in experiments])
        theta0 = np.r_[
            least_squares(Phi, join([d.y[start:, i] for d in experiments]))[0], np.zeros(nc)
        ]

    def project(theta: np.ndarray) -> np.ndarray:
        out = theta.copy()
        out[n_ab:] = stabilize(np.concatenate([[1.0], theta[n_ab:]]))[1:]
        return out

    cache: dict[bytes, list[np.ndarray]] = {}

    def full_errors(theta: np.ndarray) -> list[np.ndarray]:
        """``e = (A_i y - B_i u) / C_i`` from the first sample (zero past), per experiment."""
        key = theta.tobytes()
        if key not in cache:
            cache.clear()
            C = np.concatenate([[1.0], theta[n_ab:]])
            cache[key] = [
                inverse_filter(C, _row_equation_error(d, orders, i, theta[:n_ab]))
                for d in experiments
            ]
        return cache[key]

    def errors(theta: np.ndarray) -> np.ndarray:
        return join([e[start:] for e in full_errors(theta)])

    target = np.array([[e_row + 1, 0, 1, 1]], dtype=np.int64)

    def normal(theta: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # psi = -de/dtheta = [phi_AB, e lags] / C, exactly: filter y, u and e by 1/C
        # once, then form psi^T psi and psi^T e from lagged correlations (no psi).
        C = np.concatenate([[1.0], theta[n_ab:]])
        H = np.zeros((n_ab + nc, n_ab + nc))
        g = np.zeros(n_ab + nc)
        for d, e_full in zip(experiments, full_errors(theta), strict=True):
            S = np.empty((e_row + 2, d.N))
            S[: orders.ny] = inverse_filter(C, d.y.T)
            S[orders.ny : e_row] = inverse_filter(C, d.u.T)
            S[e_row] = inverse_filter(C, e_full)
            S[e_row + 1] = e_full
            H += lag_gram(S, blocks, blocks, start)
            g += lag_gram(S, blocks, target, start)[:, 0]
        return H, g

    if tol is None:
        tol = DEFAULT_TOL / max(1, sum(d.N - start for d in experiments))
    result = levenberg_marquardt(theta0, errors, normal, project, max_iter, tol, progress)
    return result.theta, result.covariance, result.iterations, result.converged


def armax(
    data: IdData | Sequence[IdData],
    na: object,
    nb: object,
    nc: object,
    nk: object = 1,
    max_iter: int = 50,
    tol: float | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> PolyModel:
    """Estimate an ARMAX model ``A(q) y(t) = B(q) u(t - nk) + C(q) e(t)``.

    Parameters
    ----------
    data : IdData or sequence of IdData
        Estimation data.
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and delays in samples.
    nc : int or array_like (ny,)
        Orders of the diagonal ``C``.
    max_iter : int
        Maximum Levenberg-Marquardt steps per output.  Reaching it is recorded
        in the model's report (``report.converged`` False, printed with the
        model).
    tol : float, optional
        Relative loss decrease (achieved, or predicted by the Gauss-Newton
        step) that ends the iterations; default ``0.1 / N`` (N: samples used).
        Why: ``N dV / V`` is the chi-square distance of a step in units of the
        parameter covariance, so steps that change the loss by less than
        ``0.1 / N`` move the parameters by less than ~0.3 standard deviations.
        In the flat valleys of low-SNR data Gauss-Newton otherwise takes 10-20
        such steps along poorly determined directions; on the benchmark's
        ARMAX 5/5/3/1 (25,000 samples, 15 noise realizations) the median
        parameter error is 0.184 (was 0.178 with ``1e-3 / N``) at 0 dB and
        0.024 (was 0.031) at 30 dB, with 2-3 instead of 6-8 iterations.
    progress : callable, optional
        Called after every Levenberg-Marquardt step with the step count and
        the loss (see :func:`~.pem.levenberg_marquardt`).

    Returns
    -------
    PolyModel
        Model with minimum-phase ``C`` and covariance ``lambda (psi^T psi)^-1``.
    """
    experiments = as_experiments(data)
    first = experiments[0]
    orders = make_orders(first.ny, first.nu, na=na, nb=nb, nk=nk, nc=nc)
    check_data(experiments, orders)
    thetas, covs, iters, converged = [], [], 0, True
    for i in range(orders.ny):
        theta, cov, it, done = _armax_row(experiments, orders, i, max_iter, tol, progress)
        thetas.append(theta)
        covs.append(cov)
        iters = max(iters, it)
        converged = converged and done
    return finish_model(
        'armax',
        orders,
        np.concatenate(thetas),
        sla.block_diag(*covs),
        experiments,
        'ARMAX, prediction-error method (Levenberg-Marquardt)',
        iters,
        converged=converged,
        max_iter=max_iter,
    )
