"""Lagged regression matrices and the shared tail of every estimator (report, model).

The regressor of output ``i`` at time ``t`` is::

    phi_i(t) = [-y_j(t-1) .. -y_j(t-na_ij) for each output j,
                u_j(t-nk_ij) .. u_j(t-nk_ij-nb_ij+1) for each input j]

so that ``y_i(t) = phi_i(t)^T theta_i + v_i(t)`` for an ARX row.  Matrices are
built by slicing (one copy per column, no Python loop over samples).

:func:`equation_errors` computes ``A y - B u`` with a compiled FIR kernel
(:func:`fir_add`): ``numpy.convolve`` and ``scipy.signal.lfilter`` with a
trivial denominator cost 0.3-0.5 ms per 25,000-sample channel here, the kernel
(one vectorisable pass per tap) about a tenth of that.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from .criteria import aic, fit_percent, fpe
from .dataset import IdData
from .model import EstimationReport, PolyModel
from .orders import OrderError, Orders

__all__ = [
    'arx_regressors',
    'check_data',
    'equation_errors',
    'finish_model',
    'fir_add',
    'fir_rows',
    'join',
    'lagged',
    'stack_rows',
]


@njit(cache=True)
def _fir_add(h: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    N = x.shape[0]
    for k in range(min(h.shape[0], N)):
        c = h[k]
        if c != 0.0:
            dst = out[k:]  # slice views: unit-stride loop that LLVM vectorises
            src = x[: N - k]
            for t in range(N - k):
                dst[t] += c * src[t]


def fir_add(h: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """Add ``sum_k h[k] x(t - k)`` (zero past) to ``out`` in place.

    Parameters
    ----------
    h : ndarray, shape (n,)
        FIR coefficients, ``h[0]`` at lag 0.
    x : ndarray, shape (N,)
        Signal (C-contiguous float64).
    out : ndarray, shape (N,)
        Accumulator, modified in place.
    """
    _fir_add(np.ascontiguousarray(h, dtype=float), np.ascontiguousarray(x, dtype=float), out)


def fir_rows(h: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Filter every row of ``X`` by the FIR filter ``h`` (zero initial state).

    Equals ``scipy.signal.lfilter(h, 1.0, X, axis=1)`` up to rounding.

    Parameters
    ----------
    h : ndarray, shape (n,)
        FIR coefficients.
    X : ndarray, shape (rows, N)
        Signals along axis 1.

    Returns
    -------
    ndarray, shape (rows, N)
        Filtered signals.
    """
    out = np.zeros(X.shape)
    h = np.ascontiguousarray(h, dtype=float)
    for r in range(X.shape[0]):
        _fir_add(h, np.ascontiguousarray(X[r], dtype=float), out[r])
    return out


def equation_errors(
    y: np.ndarray,
    u: np.ndarray,
    orders: Orders,
    theta: np.ndarray,
    rows: Sequence[int] | None = None,
) -> np.ndarray:
    """Equation errors ``A_i y - B_i u`` of ARX-layout rows, zero past, shape (len(rows), N).

    Parameters
    ----------
    y : ndarray, shape (N, ny)
        Outputs.
    u : ndarray, shape (N, nu)
        Inputs.
    orders : Orders
        Orders (only ``na``, ``nb``, ``nk`` are used).
    theta : ndarray
        ``A``/``B`` parameters of all rows (ARX layout, row after row), or of
        the single row ``rows[0]`` when ``len(rows) == 1`` and the size matches.
    rows : sequence of int, optional
        Output rows (default all).

    Returns
    -------
    ndarray, shape (len(rows), N)
        ``y_i(t) + sum_j sum_k a_ijk y_j(t-k) - sum_j sum_k b_ijk u_j(t-nk_ij-k)``.
    """
    rows = list(range(orders.ny)) if rows is None else list(rows)
    sizes = [int(orders.na[i].sum() + orders.nb[i].sum()) for i in range(orders.ny)]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    single = len(rows) == 1 and theta.shape[0] == sizes[rows[0]]
    yr = np.ascontiguousarray(np.asarray(y, dtype=float).T)
    ur = np.ascontiguousarray(np.asarray(u, dtype=float).T)
    out = np.empty((len(rows), yr.shape[1]))
    for r, i in enumerate(rows):
        pos = 0 if single else int(offsets[i])
        out[r] = yr[i]
        for j in range(orders.ny):
            n = int(orders.na[i, j])
            if n:
                _fir_add(np.r_[0.0, theta[pos : pos + n]], yr[j], out[r])
                pos += n
        for j in range(orders.nu):
            n, k = int(orders.nb[i, j]), int(orders.nk[i, j])
            if n:
                _fir_add(np.r_[np.zeros(k), -theta[pos : pos + n]], ur[j], out[r])
                pos += n
    return out


def stack_rows(blocks: Sequence[np.ndarray]) -> np.ndarray:
    """Stack per-experiment blocks along axis 0 (no copy for a single experiment).

    Parameters
    ----------
    blocks : sequence of ndarray
        One block per experiment.
    """
    return blocks[0] if len(blocks) == 1 else np.vstack(blocks)


def join(blocks: Sequence[np.ndarray]) -> np.ndarray:
    """Concatenate per-experiment vectors (no copy for a single experiment).

    Parameters
    ----------
    blocks : sequence of ndarray
        One vector per experiment.
    """
    return blocks[0] if len(blocks) == 1 else np.concatenate(blocks)


def lagged(signal: np.ndarray, lags: Sequence[int], start: int) -> np.ndarray:
    """Stack ``signal(t - lag)`` for ``t = start .. N-1`` as columns.

    Parameters
    ----------
    signal : ndarray, shape (N,)
        One channel.
    lags : sequence of int
        Non-negative lags, each ``<= start``.
    start : int
        First time index.

    Returns
    -------
    ndarray, shape (N - start, len(lags))
        Lagged copies.
    """
    N = signal.shape[0]
    out = np.empty((len(lags), N - start))  # filled row by row, returned transposed
    for c, lag in enumerate(lags):
        out[c] = signal[start - lag : N - lag]
    return out.T


def arx_regressors(y: np.ndarray, u: np.ndarray, orders: Orders, i: int, start: int) -> np.ndarray:
    """Regression matrix of the ``A``/``B`` part of output ``i``.

    Parameters
    ----------
    y : ndarray, shape (N, ny)
        Outputs (or instruments standing in for them).
    u : ndarray, shape (N, nu)
        Inputs.
    orders : Orders
        Model orders.
    i : int
        Output row.
    start : int
        First time index (>= ``orders.row_start(i)``).

    Returns
    -------
    ndarray, shape (N - start, sum na[i] + sum nb[i])
        ``[-y lags, u lags]`` in the parameter layout order.
    """
    width = int(orders.na[i].sum() + orders.nb[i].sum())
    out = np.empty((width, y.shape[0] - start))  # column-major: contiguous row copies
    N = y.shape[0]
    c = 0
    for j in range(orders.ny):
        for lag in range(1, orders.na[i, j] + 1):
            np.negative(y[start - lag : N - lag, j], out=out[c])
            c += 1
    for j in range(orders.nu):
        k = orders.nk[i, j]
        for lag in range(k, k + orders.nb[i, j]):
            out[c] = u[start - lag : N - lag, j]
            c += 1
    return out.T


def check_data(experiments: Sequence[IdData], orders: Orders) -> None:
    """Check that the data match the orders and hold more samples than parameters.

    Parameters
    ----------
    experiments : sequence of IdData
        The data sets.
    orders : Orders
        The model orders.

    Raises
    ------
    OrderError
        If channel counts differ from the order matrices.
    ValueError
        If there are fewer usable samples than parameters of some output row.
    """
    first = experiments[0]
    if (first.ny, first.nu) != (orders.ny, orders.nu):
        raise OrderError(
            f'orders are for ny={orders.ny}, nu={orders.nu} but the data have '
            f'ny={first.ny}, nu={first.nu}'
        )
    sizes = orders.row_sizes()
    for i in range(orders.ny):
        start = orders.row_start(i) + int(orders.nc[i] + orders.nd[i] + orders.nf[i].sum())
        usable = sum(max(0, d.N - start) for d in experiments)
        if usable <= sizes[i]:
            raise ValueError(
                f'output {i + 1} has {sizes[i]} parameters but only {usable} '
                f'usable samples: fewer samples than parameters'
            )


def finish_model(
    structure: str,
    orders: Orders,
    theta: np.ndarray,
    covariance: np.ndarray | None,
    experiments: Sequence[IdData],
    method: str,
    iterations: int = 0,
    noise_variance: np.ndarray | None = None,
    converged: bool = True,
    max_iter: int = 0,
) -> PolyModel:
    """Wrap estimated parameters in a :class:`PolyModel` with its estimation report.

    The report's fit, MSE, FPE and AIC use the one-step prediction errors of
    the model on the estimation data (zero initial state), as the toolbox does.

    Parameters
    ----------
    structure : str
        Model structure name.
    orders : Orders
        Model orders.
    theta : ndarray, shape (n_params,)
        Estimated parameters.
    covariance : ndarray, shape (n_params, n_params) or None
        Parameter covariance.
    experiments : sequence of IdData
        Estimation data.
    method : str
        Description of the numerical method.
    iterations : int
        Iteration count of an iterative method.
    noise_variance : ndarray, shape (ny, ny), optional
        Innovations covariance (default: from the prediction errors).
    converged : bool
        False if the iterative method stopped at its cap.
    max_iter : int
        The iteration cap of an iterative method (0 for direct solutions).

    Returns
    -------
    PolyModel
        The model.
    """
    first = experiments[0]
    if structure in ('arx', 'iv4'):  # e = A y - B u: compiled FIR instead of convolutions
        errors = [equation_errors(d.y, d.u, orders, theta).T for d in experiments]
    else:
        draft = PolyModel(
            structure,
            orders,
            theta,
            first.Ts,
            np.eye(orders.ny),
            None,
            first.output_names,
            first.input_names,
            first.output_units,
            first.input_units,
        )
        errors = [draft.residuals(d) for d in experiments]
    e = stack_rows(errors)
    y = stack_rows([d.y for d in experiments])
    N = e.shape[0]
    ete = e.T @ e
    lam = ete / N if noise_variance is None else noise_variance
    report = EstimationReport(
        method=method,
        n_samples=N,
        fit=fit_percent(y, y - e),
        mse=np.diag(ete) / N,
        fpe=fpe(e, orders.n_params),
        aic=aic(e, orders.n_params),
        iterations=iterations,
        converged=converged,
        max_iter=max_iter,
    )
    return PolyModel(
        structure,
        orders,
        theta,
        first.Ts,
        lam,
        covariance,
        first.output_names,
        first.input_names,
        first.output_units,
        first.input_units,
        report,
    )
