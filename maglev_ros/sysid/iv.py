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

from .arx import arx_rows, least_squares
from .dataset import IdData, as_experiments
from .model import PolyModel
from .orders import Orders, make_orders
from .regression import arx_regressors, check_data, finish_model, join, lagged, stack_rows

__all__ = ['iv4']


def _simulate(orders: Orders, theta: np.ndarray, experiments: Sequence[IdData]
              ) -> list[np.ndarray]:
    model = PolyModel('arx', orders, theta, experiments[0].Ts, np.eye(orders.ny))
    return [model.simulate(d.u) for d in experiments]


def _iv_rows(experiments: Sequence[IdData], instruments: Sequence[np.ndarray], orders: Orders,
             prefilters: Sequence[np.ndarray] | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
    thetas, covs = [], []
    for i in range(orders.ny):
        L = np.ones(1) if prefilters is None else prefilters[i]
        start = orders.row_start(i) + len(L) - 1
        Phi, Z, Y = [], [], []
        for d, x in zip(experiments, instruments, strict=True):
            y, u, xs = d.y, d.u, x
            if len(L) > 1:
                y, u, xs = (lfilter(L, 1.0, s, axis=0) for s in (y, u, x))
            Phi.append(arx_regressors(y, u, orders, i, start))
            Z.append(arx_regressors(xs, u, orders, i, start))
            Y.append(y[start:, i])
        Phi_m, Z_m, Y_v = stack_rows(Phi), stack_rows(Z), join(Y)
        ZtPhi = Z_m.T @ Phi_m
        theta = np.linalg.solve(ZtPhi, Z_m.T @ Y_v)
        resid = Y_v - Phi_m @ theta
        lam = float(resid @ resid) / max(1, len(Y_v) - len(theta))
        M = np.linalg.solve(ZtPhi, np.eye(len(theta)))
        thetas.append(theta)
        covs.append(lam * M @ (Z_m.T @ Z_m) @ M.T)
    return np.concatenate(thetas), sla.block_diag(*covs)


def _noise_prefilters(experiments: Sequence[IdData], orders: Orders,
                      theta: np.ndarray) -> list[np.ndarray]:
    filters = []
    sizes = orders.row_sizes()
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    for i in range(orders.ny):
        start = orders.row_start(i)
        th = theta[offsets[i]:offsets[i + 1]]
        w = [d.y[start:, i] - arx_regressors(d.y, d.u, orders, i, start) @ th
             for d in experiments]
        order = max(1, sizes[i])
        Phi = stack_rows([-lagged(x, range(1, order + 1), order) for x in w])
        Y = join([x[order:] for x in w])
        ar, _, _ = least_squares(Phi, Y)
        filters.append(np.concatenate([[1.0], ar]))
    return filters


def iv4(data: IdData | Sequence[IdData], na: object, nb: object, nk: object = 1) -> PolyModel:
    """Estimate an ARX model by the four-stage instrumental-variable method.

    Parameters
    ----------
    data : IdData or sequence of IdData
        Estimation data.
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and delays in samples.

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
    theta1, _, _ = arx_rows(experiments, orders)
    theta2, _ = _iv_rows(experiments, _simulate(orders, theta1, experiments), orders)
    prefilters = _noise_prefilters(experiments, orders, theta2)
    theta4, cov = _iv_rows(experiments, _simulate(orders, theta2, experiments), orders,
                           prefilters)
    return finish_model('iv4', orders, theta4, cov, experiments,
                        'IV4 (four-stage instrumental variables)')
