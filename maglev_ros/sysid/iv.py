"""Four-stage instrumental-variable estimation of ARX models (the toolbox's ``iv4``).

The stages (Ljung, *System Identification*, 2nd ed., sec. 15.3):

1. least-squares ARX estimate ``A1, B1``;
2. instruments ``x1 = B1/A1 u`` (noise-free simulated outputs) give the IV
   estimate ``A2, B2``;
3. the equation error ``w = A2 y - B2 u`` is modelled as AR, ``L(q) w = e``, of
   order ``na + nb`` (per output row);
4. instruments ``x2 = B2/A2 u``; regressors, instruments and outputs are all
   prefiltered by ``L`` and the final IV estimate is computed.

The estimate is consistent under colored equation noise (where ARX is biased),
because the instruments are built from the inputs only.  MIMO order matrices
are supported: the instruments of cross-output terms are the simulated outputs.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla
from scipy.signal import lfilter

from .arx import arx_rows, correlation_solve, row_blocks, signal_matrix
from .correlation import block_sizes, lag_gram
from .dataset import IdData, as_experiments
from .model import PolyModel
from .orders import Orders, make_orders
from .pem import stabilize
from .polynomial import pack, unpack
from .regression import check_data, finish_model

__all__ = ['iv4']


def _simulate(orders: Orders, theta: np.ndarray, experiments: Sequence[IdData],
              fallback: np.ndarray | None = None) -> list[np.ndarray]:
    """Noise-free outputs ``x = A^-1 B u`` used as instruments.

    An unstable ``A`` would make the instruments blow up: its roots are
    reflected into the unit disc (uncoupled ``A``), or the ``fallback``
    parameters are used (cross-coupled ``A``).  Any stable model gives valid
    instruments; only their efficiency is affected.
    """
    model = PolyModel('arx', orders, theta, experiments[0].Ts, np.eye(orders.ny))
    if not model.is_stable:
        if not model._coupled:
            A, B, C, D, F = unpack(orders, theta)
            for i in range(orders.ny):
                n = orders.na[i, i] + 1
                A[i, i, :n] = stabilize(A[i, i, :n])
            model = PolyModel('arx', orders, pack(orders, (A, B, C, D, F)), model.Ts,
                              np.eye(orders.ny))
        elif fallback is not None:
            return _simulate(orders, fallback, experiments)
    return [model.simulate(d.u) for d in experiments]


def _iv_rows(signals: Sequence[np.ndarray], orders: Orders, start_offset: int = 0,
             rows: Sequence[int] | None = None, covariance: bool = True
             ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """IV estimate per row from signal matrices ``[y; u; x]`` (x: instruments for y)."""
    ny = orders.ny
    thetas, covs = [], []
    for i in range(ny) if rows is None else rows:
        start = orders.row_start(i) + start_offset
        reg = row_blocks(orders, i)
        ins = row_blocks(orders, i, out_base=ny + orders.nu)
        tgt = np.array([[i, 0, 1, 1]], dtype=np.int64)
        p = block_sizes(reg)
        ZtPhi, ZtZ, PtP = np.zeros((p, p)), np.zeros((p, p)), np.zeros((p, p))
        Zty, Pty = np.zeros(p), np.zeros(p)
        yy, M = 0.0, 0
        for S in signals:
            ZtPhi += lag_gram(S, ins, reg, start)
            Zty += lag_gram(S, ins, tgt, start)[:, 0]
            if covariance:
                ZtZ += lag_gram(S, ins, ins, start)
                PtP += lag_gram(S, reg, reg, start)
                Pty += lag_gram(S, reg, tgt, start)[:, 0]
                yy += float(lag_gram(S, tgt, tgt, start)[0, 0])
            M += S.shape[1] - start
        theta = np.linalg.solve(ZtPhi, Zty)
        thetas.append(theta)
        if covariance:
            sse = max(yy - 2.0 * theta @ Pty + theta @ PtP @ theta, 0.0)
            Minv = np.linalg.solve(ZtPhi, np.eye(p))
            covs.append(sse / max(1, M - p) * Minv @ ZtZ @ Minv.T)
    return thetas, covs


def _fir_rows(h: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Filter every row of ``S`` by the FIR filter ``h`` (zero initial state)."""
    if len(h) == 1:
        return S * h[0]
    N = S.shape[1]
    return np.stack([np.convolve(row, h)[:N] for row in S])


def _noise_prefilters(experiments: Sequence[IdData], orders: Orders,
                      theta: np.ndarray) -> list[np.ndarray]:
    """AR model ``L_i`` (order na_i + nb_i) of the equation error of each row."""
    model = PolyModel('arx', orders, theta, experiments[0].Ts, np.eye(orders.ny))
    residuals = [model._filter_residuals(d.y, d.u) for d in experiments]
    filters = []
    for i, size in enumerate(orders.row_sizes()):
        start = orders.row_start(i)
        order = max(1, size)
        signals = [np.ascontiguousarray(e[start:, i])[None, :] for e in residuals]
        solved = correlation_solve(signals, np.array([[0, 1, order, -1]]), 0, order)
        if solved is None:  # white or vanishing equation error: no prefilter
            filters.append(np.ones(1))
        else:
            filters.append(np.concatenate([[1.0], solved[0]]))
    return filters


def iv4(data: IdData | Sequence[IdData], na: object, nb: object, nk: object = 1,
        refine: int = 0) -> PolyModel:
    """Estimate an ARX model by the four-stage instrumental-variable method.

    Parameters
    ----------
    data : IdData or sequence of IdData
        Estimation data.
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and delays in samples.
    refine : int
        Extra passes of stages 3-4 (prefilter and instruments rebuilt from the
        latest estimate).  0 is exactly the toolbox's four stages; one pass
        lowers the variance at low signal-to-noise ratios, where the stage-2
        estimate that builds the final instruments is poor.

    Returns
    -------
    PolyModel
        Model with structure ``'iv4'`` and the asymptotic IV covariance
        ``lambda M Z^T Z M^T``, ``M = (Z^T Phi)^-1``.
    """
    experiments = as_experiments(data)
    first = experiments[0]
    orders = make_orders(first.ny, first.nu, na=na, nb=nb, nk=nk)
    check_data(experiments, orders)
    theta1, _, _ = arx_rows(experiments, orders, refine=False)
    x1 = _simulate(orders, theta1, experiments)
    thetas2, _ = _iv_rows([signal_matrix(d, x) for d, x in zip(experiments, x1, strict=True)],
                          orders, covariance=False)
    theta2 = np.concatenate(thetas2)
    theta_prev, cov = theta2, None
    for _ in range(1 + max(0, int(refine))):
        prefilters = _noise_prefilters(experiments, orders, theta_prev)
        x2 = _simulate(orders, theta_prev, experiments, fallback=theta1)
        thetas4, covs4 = [], []
        for i, L in enumerate(prefilters):
            signals = [lfilter(L, 1.0, signal_matrix(d, x), axis=1)
                       for d, x in zip(experiments, x2, strict=True)]
            thetas, covs = _iv_rows(signals, orders, len(L) - 1, rows=[i])
            thetas4.append(thetas[0])
            covs4.append(covs[0])
        theta_prev, cov = np.concatenate(thetas4), sla.block_diag(*covs4)
    method = 'IV4 (four-stage instrumental variables)'
    if refine:
        method += f', {int(refine)} refinement pass(es)'
    return finish_model('iv4', orders, theta_prev, cov, experiments, method)
