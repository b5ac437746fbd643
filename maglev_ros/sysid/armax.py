"""ARMAX estimation by the prediction-error method (the toolbox's ``armax``).

Model ``A(q) y(t) = B(q) u(t - nk) + C(q) e(t)`` with a diagonal ``C`` for MIMO
data (``nc`` has one order per output).  Output rows share no parameters, so
each row is a separate minimization of ``sum e_i(t)^2``:

* prediction error ``e_i = (A_i y - B_i u) / C_i`` (``lfilter``, zero initial
  state at the first sample where all regressors exist);
* gradient ``psi = [phi_AB, e(t-1) .. e(t-nc)] / C_i`` (``y``, ``u`` and ``e`` are
  filtered by ``1/C_i`` once per iteration and then lagged);
* start: a high-order ARX row gives innovation estimates, then a linear
  regression on ``[phi_AB, e_hat lags]`` (Hannan-Rissanen), ``C`` reflected to
  minimum phase;
* Levenberg-Marquardt iterations (:mod:`maglev_ros.sysid.pem`) with ``C`` kept
  minimum phase by root reflection.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla
from scipy.signal import lfilter

from .arx import least_squares
from .dataset import IdData, as_experiments
from .model import PolyModel
from .orders import Orders, make_orders
from .pem import levenberg_marquardt, stabilize
from .regression import (
    arx_regressors,
    check_data,
    finish_model,
    join,
    lagged,
    stack_rows,
)

__all__ = ['armax']


def _initial_innovations(experiments: Sequence[IdData], orders: Orders, i: int,
                         extra: int) -> list[np.ndarray]:
    """Residuals of a high-order ARX row (zeros where undefined), one array per experiment."""
    na = orders.na.copy()
    nb = orders.nb.copy()
    na[i] = np.where(na[i] > 0, na[i] + extra, 0)
    na[i, i] = orders.na[i, i] + extra
    nb[i] = np.where(nb[i] > 0, nb[i] + extra, 0)
    hi = Orders(na, nb, orders.nk, orders.nc * 0, orders.nd * 0, orders.nf * 0)
    start = hi.row_start(i)
    Phis = [arx_regressors(d.y, d.u, hi, i, start) for d in experiments]
    theta, _, _ = least_squares(stack_rows(Phis), join([d.y[start:, i] for d in experiments]))
    out = []
    for d, P in zip(experiments, Phis, strict=True):
        e = np.zeros(d.N)
        e[start:] = d.y[start:, i] - P @ theta
        out.append(e)
    return out


def _armax_row(experiments: Sequence[IdData], orders: Orders, i: int, max_iter: int,
               tol: float | None) -> tuple[np.ndarray, np.ndarray, int]:
    nc = int(orders.nc[i])
    start = orders.row_start(i)
    Phis = [arx_regressors(d.y, d.u, orders, i, start) for d in experiments]
    Ys = [d.y[start:, i] for d in experiments]
    n_ab = Phis[0].shape[1]
    if nc == 0:
        Phi, Y = stack_rows(Phis), join(Ys)
        theta, Rinv, _ = least_squares(Phi, Y)
        r = Y - Phi @ theta
        return theta, float(r @ r) / max(1, len(Y) - len(theta)) * Rinv, 0
    usable = min(d.N for d in experiments) - start
    extra = int(min(max(10, 3 * nc), max(1, usable // (8 * (orders.ny + orders.nu)))))
    ehat = [e[start:] for e in _initial_innovations(experiments, orders, i, extra)]
    theta0, _, _ = least_squares(
        stack_rows([np.hstack([P, lagged(np.concatenate([np.zeros(nc), e]), range(1, nc + 1),
                                         nc)]) for P, e in zip(Phis, ehat, strict=True)]),
        join(Ys))

    def project(theta: np.ndarray) -> np.ndarray:
        out = theta.copy()
        out[n_ab:] = stabilize(np.concatenate([[1.0], theta[n_ab:]]))[1:]
        return out

    def errors(theta: np.ndarray) -> np.ndarray:
        C = np.concatenate([[1.0], theta[n_ab:]])
        return join([lfilter([1.0], C, Y - P @ theta[:n_ab])
                     for P, Y in zip(Phis, Ys, strict=True)])

    def gradient(theta: np.ndarray, e: np.ndarray) -> np.ndarray:
        # psi = [phi_AB, e lags] / C: filter the raw signals once and lag them (the
        # lagged-then-filtered columns differ only in a start-up transient).
        C = np.concatenate([[1.0], theta[n_ab:]])
        blocks, pos = [], 0
        for d in experiments:
            n = d.N - start
            seg = e[pos:pos + n]
            pos += n
            yf = lfilter([1.0], C, d.y, axis=0)
            uf = lfilter([1.0], C, d.u, axis=0) if d.nu else d.u
            ef = lfilter([1.0], C, np.concatenate([np.zeros(nc), seg]))
            psi = np.empty((n, n_ab + nc), order='F')
            psi[:, :n_ab] = arx_regressors(yf, uf, orders, i, start)
            psi[:, n_ab:] = lagged(ef, range(1, nc + 1), nc)
            blocks.append(psi)
        return stack_rows(blocks)

    result = levenberg_marquardt(theta0, errors, gradient, project, max_iter, tol)
    return result.theta, result.covariance, result.iterations


def armax(data: IdData | Sequence[IdData], na: object, nb: object, nc: object,
          nk: object = 1, max_iter: int = 50, tol: float | None = None) -> PolyModel:
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
        Maximum Levenberg-Marquardt steps per output.
    tol : float, optional
        Relative loss decrease that ends the iterations (default ``1e-3 / N``,
        see :func:`~.pem.levenberg_marquardt`).

    Returns
    -------
    PolyModel
        Model with minimum-phase ``C`` and covariance ``lambda (psi^T psi)^-1``.
    """
    experiments = as_experiments(data)
    first = experiments[0]
    orders = make_orders(first.ny, first.nu, na=na, nb=nb, nk=nk, nc=nc)
    check_data(experiments, orders)
    thetas, covs, iters = [], [], 0
    for i in range(orders.ny):
        theta, cov, it = _armax_row(experiments, orders, i, max_iter, tol)
        thetas.append(theta)
        covs.append(cov)
        iters = max(iters, it)
    return finish_model('armax', orders, np.concatenate(thetas), sla.block_diag(*covs),
                        experiments, 'ARMAX, prediction-error method (Levenberg-Marquardt)',
                        iters)
