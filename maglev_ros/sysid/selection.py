"""ARX order selection (the toolbox's ``arxstruc``, ``selstruc``, ``delayest``).

Every candidate ``(na, nb, nk)`` is fitted by least squares on the estimation
data; its loss is the mean squared one-step prediction error on the
validation data (or on the estimation data when none is given).  AIC and MDL
are computed from the estimation loss ``V`` and the parameter count ``d``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from itertools import product

import numpy as np

from .arx import arx
from .criteria import aic, mdl
from .dataset import IdData
from .orders import OrderError

__all__ = ['OrderSearch', 'arxstruc', 'delayest', 'selstruc']

CRITERIA = ('val', 'aic', 'mdl')


@dataclass(frozen=True)
class OrderSearch:
    """Table of candidate ARX structures.

    Attributes
    ----------
    orders : ndarray, shape (n, 3)
        Rows ``(na, nb, nk)``.
    loss : ndarray, shape (n,)
        Validation loss (mean squared one-step prediction error).
    aic, mdl : ndarray, shape (n,)
        Criteria on the estimation data.
    n_params : ndarray, shape (n,)
        Parameter counts ``na + nb``.
    """

    orders: np.ndarray
    loss: np.ndarray
    aic: np.ndarray
    mdl: np.ndarray
    n_params: np.ndarray


def _grid(values: int | Iterable[int], name: str) -> list[int]:
    out = [int(values)] if np.isscalar(values) else [int(v) for v in values]  # type: ignore
    if not out or min(out) < 0:
        raise OrderError(f'{name} range must be non-empty and >= 0, got {out}')
    return out


def arxstruc(
    estimation: IdData,
    validation: IdData | None = None,
    na: int | Iterable[int] = range(1, 11),
    nb: int | Iterable[int] = range(1, 11),
    nk: int | Iterable[int] = 1,
) -> OrderSearch:
    """Fit all ARX structures of a grid and tabulate their losses (SISO).

    Parameters
    ----------
    estimation : IdData
        Estimation data (one output, one input).
    validation : IdData, optional
        Validation data; default the estimation data.
    na, nb, nk : int or iterable of int
        Candidate orders.

    Returns
    -------
    OrderSearch
        One row per candidate.
    """
    if (estimation.ny, estimation.nu) != (1, 1):
        raise OrderError(
            f'arxstruc searches SISO structures; data have ny={estimation.ny}, '
            f'nu={estimation.nu} (select one output and one input)'
        )
    validation = estimation if validation is None else validation
    rows, loss, aics, mdls, npar = [], [], [], [], []
    for a, b, k in product(_grid(na, 'na'), _grid(nb, 'nb'), _grid(nk, 'nk')):
        if a + b == 0:
            continue
        model = arx(estimation, a, b, k)
        start = max(a, k + b - 1)
        e_val = model.residuals(validation)[start:]
        e_est = model.residuals(estimation)[start:]
        rows.append((a, b, k))
        loss.append(float(np.mean(e_val**2)))
        aics.append(aic(e_est, a + b))
        mdls.append(mdl(e_est, a + b))
        npar.append(a + b)
    return OrderSearch(
        np.array(rows, dtype=int),
        np.array(loss),
        np.array(aics),
        np.array(mdls),
        np.array(npar, dtype=int),
    )


def selstruc(search: OrderSearch, criterion: str = 'val') -> tuple[int, int, int]:
    """Pick the best structure of an :class:`OrderSearch`.

    Parameters
    ----------
    search : OrderSearch
        Candidates from :func:`arxstruc`.
    criterion : {'val', 'aic', 'mdl'}
        Validation loss, Akaike, or Rissanen's MDL.

    Returns
    -------
    tuple of int
        ``(na, nb, nk)``.
    """
    if criterion not in CRITERIA:
        raise ValueError(f'criterion must be one of {CRITERIA}, got {criterion!r}')
    values = {'val': search.loss, 'aic': search.aic, 'mdl': search.mdl}[criterion]
    best = int(np.argmin(values))
    return tuple(int(v) for v in search.orders[best])  # type: ignore[return-value]


def delayest(data: IdData, na: int = 2, nb: int = 2, nk: Iterable[int] = range(0, 11)) -> int:
    """Estimate the input delay in samples by the ARX loss over a range of ``nk``.

    Parameters
    ----------
    data : IdData
        SISO data.
    na, nb : int
        ARX orders of the trial models.
    nk : iterable of int
        Candidate delays in samples.

    Returns
    -------
    int
        The delay with the lowest one-step prediction loss.
    """
    search = arxstruc(data, data, na, nb, nk)
    return int(search.orders[int(np.argmin(search.loss)), 2])
