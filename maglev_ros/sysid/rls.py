"""Recursive least-squares ARX with a forgetting factor (for online identification).

For each output row ``i`` with regressor ``phi(t)`` (as in :func:`~.arx.arx`)::

    K      = P phi / (lambda + phi^T P phi)
    theta += K (y_i(t) - phi^T theta)
    P      = (P - K phi^T P) / lambda

``lambda = 1`` gives the exact recursive form of batch least squares (up to
the prior ``P0 = p0 I``); ``lambda < 1`` forgets old data with a memory of about
``1 / (1 - lambda)`` samples.  Signals before the first sample are taken as zero.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from .dataset import IdData
from .model import PolyModel
from .orders import Orders, make_orders
from .regression import arx_regressors

__all__ = ['RecursiveArx', 'RlsResult', 'rls_arx', 'rls_step']


def _check_forgetting(forgetting: float, p0: float) -> None:
    if not 0.0 < forgetting <= 1.0:
        raise ValueError(f'forgetting factor must be in (0, 1], got {forgetting!r}')
    if not p0 > 0:
        raise ValueError(f'p0 (initial covariance scale) must be > 0, got {p0!r}')


@njit(cache=True)
def rls_step(
    P: np.ndarray, theta: np.ndarray, phi: np.ndarray, y: float, lam: float
) -> float:  # pragma: no cover - numba
    """One RLS update of ``theta`` (p,) and ``P`` (p, p) in place; return the prior error.

    ``P`` is updated as ``(P - Pphi Pphi^T / denom) / lam``, element by element,
    so that it stays exactly symmetric: with ``lam < 1`` the rounding
    asymmetry of ``P - K (P phi)^T`` grows without bound (the estimate drifts
    from the least-squares one after a few thousand samples).

    Parameters
    ----------
    P : ndarray, shape (p, p)
        Covariance, updated in place.
    theta : ndarray, shape (p,)
        Parameters, updated in place.
    phi : ndarray, shape (p,)
        Regressor.
    y : float
        Measured output.
    lam : float
        Forgetting factor in (0, 1].
    """
    p = phi.shape[0]
    Pphi = np.empty(p)
    err = y
    denom = lam
    for a in range(p):
        acc = 0.0
        for b in range(p):
            acc += P[a, b] * phi[b]
        Pphi[a] = acc
        denom += phi[a] * acc
        err -= phi[a] * theta[a]
    for a in range(p):
        theta[a] += Pphi[a] / denom * err
    for a in range(p):
        for b in range(p):
            P[a, b] = (P[a, b] - Pphi[a] * Pphi[b] / denom) / lam
    return err


@njit(cache=True)
def _rls_run(
    Phi: np.ndarray, Y: np.ndarray, lam: float, P: np.ndarray, theta: np.ndarray
) -> np.ndarray:  # pragma: no cover - numba
    N, p = Phi.shape
    history = np.empty((N, p))
    for t in range(N):
        rls_step(P, theta, Phi[t], Y[t], lam)
        history[t] = theta
    return history


@dataclass(frozen=True)
class RlsResult:
    """Outcome of :func:`rls_arx`.

    Attributes
    ----------
    theta : ndarray, shape (N, n_params)
        Parameter estimate after each sample (layout of :mod:`.orders`).
    model : PolyModel
        ARX model from the final estimate.
    """

    theta: np.ndarray
    model: PolyModel


def rls_arx(
    data: IdData, na: object, nb: object, nk: object = 1, forgetting: float = 1.0, p0: float = 1e4
) -> RlsResult:
    """Run recursive least-squares ARX over a data set (numba kernel).

    Parameters
    ----------
    data : IdData
        Input/output data.
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and delays in samples.
    forgetting : float
        Forgetting factor ``lambda`` in (0, 1].
    p0 : float
        Initial covariance ``P0 = p0 I`` (large = weak prior at ``theta = 0``).

    Returns
    -------
    RlsResult
        Parameter trajectory and final model.
    """
    _check_forgetting(forgetting, p0)
    orders = make_orders(data.ny, data.nu, na=na, nb=nb, nk=nk)
    lag = max(orders.row_start(i) for i in range(orders.ny))
    y = np.vstack([np.zeros((lag, data.ny)), data.y])
    u = np.vstack([np.zeros((lag, data.nu)), data.u])
    histories = []
    for i in range(orders.ny):
        Phi = np.ascontiguousarray(arx_regressors(y, u, orders, i, lag))
        p = Phi.shape[1]
        histories.append(
            _rls_run(
                Phi,
                np.ascontiguousarray(data.y[:, i]),
                float(forgetting),
                p0 * np.eye(p),
                np.zeros(p),
            )
        )
    theta = np.hstack(histories)
    model = PolyModel(
        'arx',
        orders,
        theta[-1],
        data.Ts,
        np.eye(orders.ny),
        None,
        data.output_names,
        data.input_names,
        data.output_units,
        data.input_units,
    )
    return RlsResult(theta=theta, model=model)


class RecursiveArx:
    """Sample-by-sample RLS ARX estimator (state lives in the object).

    Parameters
    ----------
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and delays in samples.
    ny, nu : int
        Number of outputs and inputs.
    forgetting : float
        Forgetting factor in (0, 1].
    p0 : float
        Initial covariance scale.
    """

    def __init__(
        self,
        na: object,
        nb: object,
        nk: object = 1,
        ny: int = 1,
        nu: int = 1,
        forgetting: float = 0.99,
        p0: float = 1e4,
    ) -> None:
        _check_forgetting(forgetting, p0)
        self.orders: Orders = make_orders(ny, nu, na=na, nb=nb, nk=nk)
        self.forgetting = float(forgetting)
        self._lag = max(self.orders.row_start(i) for i in range(ny)) + 1
        self._y = np.zeros((self._lag + 1, ny))
        self._u = np.zeros((self._lag + 1, nu))
        sizes = self.orders.row_sizes()
        self._theta = [np.zeros(s) for s in sizes]
        self._P = [p0 * np.eye(s) for s in sizes]
        self.n_updates = 0

    @property
    def theta(self) -> np.ndarray:
        """Current parameter vector, shape (n_params,)."""
        return np.concatenate(self._theta)

    def update(
        self, y: Sequence[float] | np.ndarray, u: Sequence[float] | np.ndarray
    ) -> np.ndarray:
        """Add one sample ``y(t)`` (ny,) and ``u(t)`` (nu,); return the new parameters.

        Parameters
        ----------
        y : array_like, shape (ny,)
            Output sample y(t).
        u : array_like, shape (nu,)
            Input sample u(t).
        """
        y = np.atleast_1d(np.asarray(y, dtype=float))
        u = np.atleast_1d(np.asarray(u, dtype=float))
        o = self.orders
        if y.shape != (o.ny,) or u.shape != (o.nu,):
            raise ValueError(
                f'update needs y of shape ({o.ny},) and u of shape ({o.nu},), '
                f'got {y.shape} and {u.shape}'
            )
        self._u = np.roll(self._u, 1, axis=0)
        self._u[0] = u
        self._y = np.roll(self._y, 1, axis=0)
        self._y[0] = y
        # histories are newest-last for arx_regressors: time index lag = now
        yh, uh = self._y[::-1], self._u[::-1]
        now = self._lag
        for i in range(o.ny):
            phi = np.ascontiguousarray(arx_regressors(yh, uh, o, i, now)[0])
            rls_step(self._P[i], self._theta[i], phi, float(y[i]), self.forgetting)
        self.n_updates += 1
        return self.theta

    def model(self, Ts: float) -> PolyModel:
        """Return the current estimate as an ARX :class:`PolyModel` with sample time ``Ts`` (s).

        Parameters
        ----------
        Ts : float
            Sample time, s.
        """
        return PolyModel('arx', self.orders, self.theta, Ts, np.eye(self.orders.ny))
