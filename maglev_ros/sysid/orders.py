"""Model orders in the toolbox's conventions and the parameter-vector layout.

A polynomial model with ``ny`` outputs and ``nu`` inputs is::

    A(q) y(t) = sum_j B_ij(q) / F_ij(q) u_j(t - nk_ij) + C_i(q) / D_i(q) e_i(t)

with ``na`` an ``ny x ny`` matrix (``A_ii`` monic of degree ``na_ii``; ``A_ij``,
``i != j``, starts at lag 1), ``nb``, ``nk``, ``nf`` ``ny x nu`` matrices (``B_ij`` has
``nb_ij`` coefficients starting at lag ``nk_ij``) and ``nc``, ``nd`` vectors of
length ``ny``.  The parameter vector is ordered output by output; within
output ``i``: the coefficients of ``A_i1 .. A_i,ny``, ``B_i1 .. B_i,nu``, ``C_i``,
``D_i``, ``F_i1 .. F_i,nu``, each by increasing lag.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['OrderError', 'Orders', 'make_orders']


class OrderError(ValueError):
    """Order matrices that are inconsistent with each other or with the data."""


def _matrix(value: object, shape: tuple[int, ...], arg: str) -> np.ndarray:
    array = np.asarray(value)
    if array.size == 0 and int(np.prod(shape)) == 0:
        return np.zeros(shape, dtype=int)
    if array.ndim == 0:
        array = np.full(shape, array)
    elif array.size == int(np.prod(shape)) and array.ndim <= 2:
        array = array.reshape(shape)
    else:
        raise OrderError(f'{arg} must be a scalar or have shape {shape}, got {array.shape}')
    if not np.all(np.isfinite(array.astype(float))) or np.any(array != np.round(array)):
        raise OrderError(f'{arg} must hold integers, got {array.tolist()}')
    array = array.astype(int)
    if np.any(array < 0):
        raise OrderError(f'{arg} must be >= 0, got {array.tolist()}')
    return array


@dataclass(frozen=True, eq=False)
class Orders:
    """Orders of a polynomial model (all integer arrays, see module docstring).

    Attributes
    ----------
    na : ndarray, shape (ny, ny)
    nb, nk, nf : ndarray, shape (ny, nu)
    nc, nd : ndarray, shape (ny,)
    """

    na: np.ndarray
    nb: np.ndarray
    nk: np.ndarray
    nc: np.ndarray
    nd: np.ndarray
    nf: np.ndarray

    @property
    def ny(self) -> int:
        """Number of outputs."""
        return self.na.shape[0]

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return self.nb.shape[1]

    def row_sizes(self) -> list[int]:
        """Return the number of free parameters of each output row."""
        return [
            int(self.na[i].sum() + self.nb[i].sum() + self.nc[i] + self.nd[i] + self.nf[i].sum())
            for i in range(self.ny)
        ]

    @property
    def n_params(self) -> int:
        """Total number of free parameters."""
        return int(sum(self.row_sizes()))

    def row_start(self, i: int) -> int:
        """Index of the first sample with all regressors of output ``i`` available.

        Parameters
        ----------
        i : int
            Output index.
        """
        lags = [int(self.na[i].max(initial=0))]
        lags += [
            int(self.nk[i, j] + self.nb[i, j] - 1) for j in range(self.nu) if self.nb[i, j] > 0
        ]
        return max([0, *lags])

    def as_dict(self) -> dict[str, list]:
        """Return the orders as nested lists (for JSON/YAML)."""
        return {k: getattr(self, k).tolist() for k in ('na', 'nb', 'nk', 'nc', 'nd', 'nf')}

    def describe(self) -> str:
        """Return the orders in the toolbox's text (``na=2 nb=2 nk=1`` or matrices)."""
        parts = []
        for key in ('na', 'nb', 'nc', 'nd', 'nf', 'nk'):
            value = getattr(self, key)
            if key == 'na' and not np.any(value) and (np.any(self.nf) or np.any(self.nd)):
                continue
            if key in ('nc', 'nd', 'nf') and not np.any(value):
                continue
            if key == 'nk' and not np.any(self.nb):
                continue
            if value.size == 1:
                parts.append(f'{key}={int(value.ravel()[0])}')
            else:
                rows = ';'.join(
                    ' '.join(str(v) for v in np.atleast_1d(r))
                    for r in (value if value.ndim == 2 else value[:, None])
                )
                parts.append(f'{key}=[{rows}]')
        return '  '.join(parts)


def make_orders(
    ny: int,
    nu: int,
    na: object = 0,
    nb: object = 0,
    nk: object = 1,
    nc: object = 0,
    nd: object = 0,
    nf: object = 0,
) -> Orders:
    """Build and check :class:`Orders`, broadcasting scalars to the full shapes.

    Parameters
    ----------
    ny, nu : int
        Number of outputs and inputs.
    na : int or array_like (ny, ny)
        Orders of the ``A`` polynomials.
    nb, nk, nf : int or array_like (ny, nu)
        Number of ``B`` coefficients, input delays in samples, orders of ``F``.
    nc, nd : int or array_like (ny,)
        Orders of ``C`` and ``D``.

    Returns
    -------
    Orders
        Validated orders.

    Raises
    ------
    OrderError
        For wrong shapes, negative or non-integer orders, or ``F``/``D`` combined
        with a non-diagonal ``A``.
    """
    if ny < 1:
        raise OrderError(f'ny must be >= 1, got {ny}')
    orders = Orders(
        na=_matrix(na, (ny, ny), 'na'),
        nb=_matrix(nb, (ny, nu), 'nb'),
        nk=_matrix(nk, (ny, nu), 'nk'),
        nc=_matrix(nc, (ny,), 'nc'),
        nd=_matrix(nd, (ny,), 'nd'),
        nf=_matrix(nf, (ny, nu), 'nf'),
    )
    offdiag = orders.na[~np.eye(ny, dtype=bool)]
    if (np.any(orders.nf) or np.any(orders.nd)) and np.any(offdiag):
        raise OrderError(
            'F or D polynomials need a diagonal na (no cross-output A terms), '
            f'got na={orders.na.tolist()}'
        )
    return orders
