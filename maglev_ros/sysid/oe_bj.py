"""Output-error and Box-Jenkins estimation by the prediction-error method (SISO).

OE: ``y(t) = B(q)/F(q) u(t - nk) + e(t)``, orders ``[nb nf nk]``.
BJ: ``y(t) = B(q)/F(q) u(t - nk) + C(q)/D(q) e(t)``, orders ``[nb nc nd nf nk]``.

Prediction error ``e = D/C (y - B/F u)`` (zero initial states, ``lfilter``);
gradient, with ``w = B/F u`` and ``v = y - w``::

    psi_b = D/(C F) u(t-nk-k),  psi_f = -D/(C F) w(t-k),
    psi_c = e(t-k) / C,         psi_d = -v(t-k) / C.

Start: ``F, B`` from the four-stage IV estimate (an ARX with ``na = nf``), then
for BJ an ARMA model of ``v`` by Hannan-Rissanen; all of ``F``, ``C``, ``D`` are
kept stable by root reflection during the Levenberg-Marquardt iterations.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.signal import lfilter

from .arx import least_squares
from .dataset import IdData, as_experiments
from .iv import iv4
from .model import PolyModel
from .orders import OrderError, make_orders
from .pem import from_jacobian, levenberg_marquardt, shift, stabilize
from .regression import check_data, finish_model, lagged

__all__ = ['bj', 'oe']


def _arma_start(v: Sequence[np.ndarray], nc: int, nd: int) -> tuple[np.ndarray, np.ndarray]:
    """Hannan-Rissanen ARMA(nd, nc) estimate of ``D v = C e``: returns ``(C, D)``."""
    if nc == 0 and nd == 0:
        return np.ones(1), np.ones(1)
    n_hi = max(20, 3 * (nc + nd))
    Phi = np.vstack([-lagged(x, range(1, n_hi + 1), n_hi) for x in v])
    ar, _, _ = least_squares(Phi, np.concatenate([x[n_hi:] for x in v]))
    ehat = [lfilter(np.concatenate([[1.0], ar]), [1.0], x) for x in v]
    start = max(nc, nd)
    blocks = []
    for x, e in zip(v, ehat, strict=True):
        cols = [-lagged(x, range(1, nd + 1), start)] if nd else []
        cols += [lagged(e, range(1, nc + 1), start)] if nc else []
        blocks.append(np.hstack(cols))
    theta, _, _ = least_squares(np.vstack(blocks), np.concatenate([x[start:] for x in v]))
    D = stabilize(np.concatenate([[1.0], theta[:nd]]))
    C = stabilize(np.concatenate([[1.0], theta[nd:]]))
    return C, D


def _box_jenkins(
    data: IdData | Sequence[IdData],
    nb: int,
    nc: int,
    nd: int,
    nf: int,
    nk: int,
    max_iter: int,
    tol: float,
) -> PolyModel:
    experiments = as_experiments(data)
    first = experiments[0]
    if (first.ny, first.nu) != (1, 1):
        raise OrderError(
            f'OE and BJ are single-input single-output here; the data have '
            f'ny={first.ny}, nu={first.nu} (select one output and one input)'
        )
    orders = make_orders(1, 1, nb=nb, nc=nc, nd=nd, nf=nf, nk=nk)
    check_data(experiments, orders)
    if nb < 1:
        raise OrderError(f'nb must be >= 1 for OE/BJ, got {nb}')
    start_model = iv4(experiments, nf, nb, nk) if nf else None
    if start_model is not None:
        F0 = stabilize(start_model.polynomial('A'))
        b0 = start_model.polynomial('B')[nk:]
    else:
        F0 = np.ones(1)
        Phi = np.vstack([lagged(d.u[:, 0], range(nk, nk + nb), nk + nb - 1) for d in experiments])
        b0, _, _ = least_squares(Phi, np.concatenate([d.y[nk + nb - 1 :, 0] for d in experiments]))
    us = [d.u[:, 0] for d in experiments]
    ys = [d.y[:, 0] for d in experiments]

    def split(theta: np.ndarray) -> tuple[np.ndarray, ...]:
        B = np.concatenate([np.zeros(nk), theta[:nb]])
        C = np.concatenate([[1.0], theta[nb : nb + nc]])
        D = np.concatenate([[1.0], theta[nb + nc : nb + nc + nd]])
        F = np.concatenate([[1.0], theta[nb + nc + nd :]])
        return B, C, D, F

    C0, D0 = np.ones(1), np.ones(1)
    if nc or nd:
        v0 = [
            y - lfilter(np.concatenate([np.zeros(nk), b0]), F0, u)
            for y, u in zip(ys, us, strict=True)
        ]
        C0, D0 = _arma_start(v0, nc, nd)
    theta0 = np.concatenate([b0, C0[1:], D0[1:], F0[1:]])

    def project(theta: np.ndarray) -> np.ndarray:
        B, C, D, F = split(theta)
        return np.concatenate([theta[:nb], stabilize(C)[1:], stabilize(D)[1:], stabilize(F)[1:]])

    def errors(theta: np.ndarray) -> np.ndarray:
        B, C, D, F = split(theta)
        out = []
        for y, u in zip(ys, us, strict=True):
            v = y - lfilter(B, F, u)
            out.append(lfilter(D, C, v) if (nc or nd) else v)
        return np.concatenate(out)

    def gradient(theta: np.ndarray, e: np.ndarray) -> np.ndarray:
        B, C, D, F = split(theta)
        blocks, pos = [], 0
        for y, u in zip(ys, us, strict=True):
            ex = e[pos : pos + len(y)]
            pos += len(y)
            w = lfilter(B, F, u)
            cf = np.convolve(C, F)
            uf = lfilter(D, cf, u)
            wf = lfilter(D, cf, w)
            cols = [shift(uf, nk + k) for k in range(nb)]
            cols += [shift(lfilter([1.0], C, ex), k) for k in range(1, nc + 1)]
            if nd:
                vc = lfilter([1.0], C, y - w)
                cols += [-shift(vc, k) for k in range(1, nd + 1)]
            cols += [-shift(wf, k) for k in range(1, nf + 1)]
            blocks.append(np.column_stack(cols))
        return np.vstack(blocks)

    result = levenberg_marquardt(theta0, errors, from_jacobian(gradient), project, max_iter, tol)
    structure = 'bj' if (nc or nd) else 'oe'
    name = 'BJ' if structure == 'bj' else 'OE'
    return finish_model(
        structure,
        orders,
        result.theta,
        result.covariance,
        experiments,
        f'{name}, prediction-error method (Levenberg-Marquardt)',
        result.iterations,
        converged=result.converged,
        max_iter=max_iter,
    )


def oe(
    data: IdData | Sequence[IdData],
    nb: int,
    nf: int,
    nk: int = 1,
    max_iter: int = 100,
    tol: float | None = None,
) -> PolyModel:
    """Estimate an output-error model ``y = B/F u(t - nk) + e`` (SISO).

    Parameters
    ----------
    data : IdData or sequence of IdData
        Single-input single-output estimation data.
    nb : int
        Number of ``B`` coefficients (>= 1).
    nf : int
        Order of ``F``.
    nk : int
        Input delay in samples.
    max_iter : int
        Maximum Levenberg-Marquardt steps.
    tol : float, optional
        Relative loss decrease that ends the iterations (default ``1e-3 / N``,
        see :func:`~.pem.levenberg_marquardt`).

    Returns
    -------
    PolyModel
        Model with structure ``'oe'``, stable ``F``.
    """
    return _box_jenkins(data, int(nb), 0, 0, int(nf), int(nk), max_iter, tol)


def bj(
    data: IdData | Sequence[IdData],
    nb: int,
    nc: int,
    nd: int,
    nf: int,
    nk: int = 1,
    max_iter: int = 100,
    tol: float | None = None,
) -> PolyModel:
    """Estimate a Box-Jenkins model ``y = B/F u(t - nk) + C/D e`` (SISO).

    Parameters
    ----------
    data : IdData or sequence of IdData
        Single-input single-output estimation data.
    nb, nc, nd, nf : int
        Orders (``nb`` = number of ``B`` coefficients), the toolbox's
        ``[nb nc nd nf nk]``.
    nk : int
        Input delay in samples.
    max_iter : int
        Maximum Levenberg-Marquardt steps.
    tol : float, optional
        Relative loss decrease that ends the iterations (default ``1e-3 / N``,
        see :func:`~.pem.levenberg_marquardt`).

    Returns
    -------
    PolyModel
        Model with structure ``'bj'``; ``F`` and ``D`` stable, ``C`` minimum phase.
    """
    return _box_jenkins(data, int(nb), int(nc), int(nd), int(nf), int(nk), max_iter, tol)
