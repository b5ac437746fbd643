"""Online recursive ARX: the numerical core of the identifier node.

:class:`OnlineArx` is :class:`~.rls.RecursiveArx` (the same update, the same
numbers) with what an online identifier needs around it:

* **start**: by default a row is updated only once its regressor is complete
  (sample ``orders.row_start(i)`` on), as batch :func:`~.arx.arx` does, so that
  with forgetting factor 1 and a weak prior the estimate is the batch ARX of
  the same samples; ``wait_for_history=False`` takes the signals before the
  first sample as zero, exactly as ``RecursiveArx``;
* **forgetting factor** ``lambda`` (default 1, as MATLAB's ``recursiveARX``) and
  the **initial covariance** ``P0 = p0 I`` (default 1e4, as MATLAB);
* an optional **sliding window** of ``W`` samples: after each update the sample
  that leaves the window is removed again (a rank-one downdate with its
  remaining weight ``lambda^W``), so the estimate is the (weighted) least
  squares of the last ``W`` samples (plus the decayed prior);
* **reset** to the initial state;
* the a-priori **one-step prediction error** ``y(t) - phi(t)^T theta(t-1)`` and
  the **fit** of those predictions over a sliding window (percent, as
  :func:`~.criteria.fit_percent`);
* diagnostics: the **covariance trace** and the **parameter drift** since the
  previous :meth:`OnlineArx.status`.

:func:`coefficient_layout` describes the parameter vector for a
``std_msgs/Float64MultiArray``: dimension labels name the polynomials and
their orders.  Pure functions and numpy only (no rclpy).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .model import PolyModel
from .orders import Orders, make_orders
from .rls import rls_step

__all__ = ['CoefficientLayout', 'IdentifierStatus', 'OnlineArx', 'coefficient_layout']


def _check(forgetting: float, p0: float, window: int | None, fit_window: int) -> None:
    if not 0.0 < forgetting <= 1.0:
        raise ValueError(f'forgetting factor must be in (0, 1], got {forgetting!r}')
    if not (np.isfinite(p0) and p0 > 0):
        raise ValueError(f'initial covariance must be > 0, got {p0!r}')
    if window is not None and (not isinstance(window, (int, np.integer)) or window < 1):
        raise ValueError(f'window must be a sample count >= 1 or None, got {window!r}')
    if not isinstance(fit_window, (int, np.integer)) or fit_window < 2:
        raise ValueError(f'fit_window must be a sample count >= 2, got {fit_window!r}')


@dataclass(frozen=True)
class IdentifierStatus:
    """A snapshot of :class:`OnlineArx`.

    Attributes
    ----------
    samples : int
        Samples given to :meth:`OnlineArx.update` since the start or reset.
    theta : ndarray, shape (n_params,)
        Parameters (layout of :mod:`.orders`).
    prediction_error : ndarray, shape (ny,)
        Last a-priori one-step prediction error, output units (NaN before the
        first update of a row).
    fit : ndarray, shape (ny,)
        Fit of the one-step predictions over the last ``fit_window`` samples,
        percent (NaN until two predictions exist).
    covariance_trace : float
        Trace of the parameter covariance ``P`` (all rows), parameter units
        squared over output units squared.
    drift : float
        ``||theta - theta_prev||``, ``theta_prev`` the parameters at the
        previous status (0 at the first).
    relative_drift : float
        ``drift / max(||theta||, tiny)``.
    """

    samples: int
    theta: np.ndarray
    prediction_error: np.ndarray
    fit: np.ndarray
    covariance_trace: float
    drift: float
    relative_drift: float


class OnlineArx:
    """Recursive least-squares ARX, sample by sample (see the module docstring).

    Parameters
    ----------
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and input delays, samples.
    ny, nu : int
        Numbers of outputs and inputs.
    forgetting : float
        Forgetting factor in (0, 1] (1: no forgetting).
    initial_covariance : float
        ``p0`` of ``P0 = p0 I`` (large: weak prior at ``theta = 0``).
    window : int, optional
        Sliding-window length in samples (None: no window).
    fit_window : int
        Samples of the prediction-fit window.
    wait_for_history : bool
        Update a row only once its regressor is complete (default; as batch
        ARX).  False: zeros before the first sample (as ``RecursiveArx``).
    """

    def __init__(
        self,
        na: object,
        nb: object,
        nk: object = 1,
        ny: int = 1,
        nu: int = 1,
        forgetting: float = 1.0,
        initial_covariance: float = 1e4,
        window: int | None = None,
        fit_window: int = 1000,
        wait_for_history: bool = True,
    ) -> None:
        _check(forgetting, initial_covariance, window, fit_window)
        self.orders: Orders = make_orders(ny, nu, na=na, nb=nb, nk=nk)
        self.forgetting = float(forgetting)
        self.initial_covariance = float(initial_covariance)
        self.window = None if window is None else int(window)
        self.fit_window = int(fit_window)
        self.wait_for_history = bool(wait_for_history)
        o = self.orders
        self._ylags = max(1, int(o.na.max(initial=0)))
        self._ulags = max(1, int((o.nk + o.nb).max(initial=1)))
        # regressor of row i = flat[index_i], flat = [-y(t-1..), u(t..)] channel-major
        self._index = []
        for i in range(o.ny):
            idx = []
            for j in range(o.ny):
                idx += [j * self._ylags + lag - 1 for lag in range(1, o.na[i, j] + 1)]
            base = o.ny * self._ylags
            for j in range(o.nu):
                k = int(o.nk[i, j])
                idx += [base + j * self._ulags + lag for lag in range(k, k + o.nb[i, j])]
            self._index.append(np.array(idx, dtype=np.intp))
        self._starts = [o.row_start(i) for i in range(o.ny)]
        self._sizes = o.row_sizes()
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Return to the initial state: ``theta = 0``, ``P = P0``, empty histories."""
        o = self.orders
        self._yh = np.zeros((o.ny, self._ylags))  # column 0: y(t-1)
        self._uh = np.zeros((o.nu, self._ulags))  # column 0: u(t)
        self._theta = [np.zeros(s) for s in self._sizes]
        self._P = [self.initial_covariance * np.eye(s) for s in self._sizes]
        self.samples = 0
        self._updates = np.zeros(o.ny, dtype=np.int64)
        self._last_error = np.full(o.ny, np.nan)
        self._fit_y = np.full((self.fit_window, o.ny), np.nan)
        self._fit_e = np.full((self.fit_window, o.ny), np.nan)
        self._window: list[deque[tuple[np.ndarray, float]]] = [deque() for _ in range(o.ny)]
        self._theta_prev: np.ndarray | None = None

    @property
    def theta(self) -> np.ndarray:
        """Current parameters, shape (n_params,) (layout of :mod:`.orders`)."""
        return np.concatenate(self._theta)

    @property
    def covariance(self) -> np.ndarray:
        """Current ``P``, block diagonal, shape (n_params, n_params)."""
        from scipy.linalg import block_diag

        return block_diag(*self._P)

    # --------------------------------------------------------------- updating
    def update(
        self, y: Sequence[float] | np.ndarray, u: Sequence[float] | np.ndarray
    ) -> np.ndarray:
        """Add the sample ``y(t)`` (ny,), ``u(t)`` (nu,); return the prediction error (ny,).

        The error is ``y(t) - phi(t)^T theta(t-1)``, before the update (NaN for
        a row that is still waiting for its history).

        Parameters
        ----------
        y : array_like, shape (ny,)
            Outputs at ``t``, output units.
        u : array_like, shape (nu,)
            Inputs at ``t``, input units.

        Raises
        ------
        ValueError
            Wrong shapes or non-finite values (the state is left unchanged).
        """
        o = self.orders
        y = np.atleast_1d(np.asarray(y, dtype=float))
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if y.shape != (o.ny,) or u.shape != (o.nu,):
            raise ValueError(
                f'update needs y of shape ({o.ny},) and u of shape ({o.nu},), '
                f'got {y.shape} and {u.shape}'
            )
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
            raise ValueError(f'samples must be finite, got y={y.tolist()} u={u.tolist()}')
        self._uh[:, 1:] = self._uh[:, :-1]
        self._uh[:, 0] = u
        flat = np.concatenate([-self._yh.ravel(), self._uh.ravel()])
        errors = np.full(o.ny, np.nan)
        for i in range(o.ny):
            if self.wait_for_history and self.samples < self._starts[i]:
                continue
            phi = flat[self._index[i]]
            # the update of RecursiveArx and rls_arx (one compiled step)
            errors[i] = rls_step(self._P[i], self._theta[i], phi, float(y[i]), self.forgetting)
            self._updates[i] += 1
            if self.window is not None:
                self._slide(i, phi, float(y[i]))
        self._yh[:, 1:] = self._yh[:, :-1]
        self._yh[:, 0] = y
        slot = self.samples % self.fit_window
        self._fit_y[slot] = y
        self._fit_e[slot] = errors
        self._last_error = errors
        self.samples += 1
        return errors

    def _slide(self, i: int, phi: np.ndarray, y: float) -> None:
        """Keep row ``i``'s window: remove the sample that leaves it (rank-one downdate)."""
        kept = self._window[i]
        kept.append((phi, y))
        if len(kept) <= self.window:
            return
        old_phi, old_y = kept.popleft()
        weight = self.forgetting**self.window  # its weight now, after W more updates
        P, theta = self._P[i], self._theta[i]
        Pphi = P @ old_phi
        denom = 1.0 / weight - old_phi @ Pphi
        theta -= Pphi / denom * (old_y - old_phi @ theta)
        P += np.outer(Pphi, Pphi) / denom  # exactly symmetric, as rls_step

    # ------------------------------------------------------------ diagnostics
    def fit(self) -> np.ndarray:
        """Fit of the one-step predictions over the fit window, percent, shape (ny,)."""
        out = np.full(self.orders.ny, np.nan)
        for i in range(self.orders.ny):
            ok = np.isfinite(self._fit_e[:, i])
            if np.count_nonzero(ok) < 2:
                continue
            y, e = self._fit_y[ok, i], self._fit_e[ok, i]
            spread = np.linalg.norm(y - y.mean())
            out[i] = 100.0 * (1.0 - np.linalg.norm(e) / spread) if spread > 0 else np.nan
        return out

    def status(self) -> IdentifierStatus:
        """Snapshot with diagnostics; the drift is measured from the previous call."""
        theta = self.theta
        drift = (
            0.0 if self._theta_prev is None else float(np.linalg.norm(theta - self._theta_prev))
        )
        self._theta_prev = theta.copy()
        return IdentifierStatus(
            samples=self.samples,
            theta=theta,
            prediction_error=self._last_error.copy(),
            fit=self.fit(),
            covariance_trace=float(sum(np.trace(P) for P in self._P)),
            drift=drift,
            relative_drift=drift / max(float(np.linalg.norm(theta)), np.finfo(float).tiny),
        )

    def model(
        self,
        Ts: float,
        output_names: Sequence[str] = (),
        input_names: Sequence[str] = (),
    ) -> PolyModel:
        """Return the current estimate as an ARX :class:`PolyModel` (sample time ``Ts``, s).

        Parameters
        ----------
        Ts : float
            Sample time, s.
        output_names, input_names : sequence of str
            Channel names (default ``y1 ..``, ``u1 ..``).
        """
        return PolyModel(
            'arx',
            self.orders,
            self.theta,
            Ts,
            np.eye(self.orders.ny),
            None,
            tuple(output_names),
            tuple(input_names),
        )


@dataclass(frozen=True)
class CoefficientLayout:
    """Layout of an ARX parameter vector for a ``std_msgs/Float64MultiArray``.

    ``dims[0]`` is ``('theta', n_params, n_params)``: to a generic reader the
    message is a plain vector.  Each further dimension names one polynomial
    block: its label (``'A[y1,y1] na=2'``, ``'B[y1,ux] nb=3 nk=1'``), its
    size (coefficient count) and, in ``stride``, the offset of its first
    coefficient in ``data`` (blocks are contiguous, by increasing lag: ``A``
    from lag 1, ``B`` from lag ``nk``).

    Attributes
    ----------
    dims : tuple of (str, int, int)
        ``(label, size, stride)`` of each ``MultiArrayDimension``.
    data : ndarray, shape (n_params,)
        The coefficients.
    """

    dims: tuple[tuple[str, int, int], ...]
    data: np.ndarray

    @property
    def labels(self) -> tuple[str, ...]:
        """Dimension labels."""
        return tuple(d[0] for d in self.dims)

    def block(self, label: str) -> np.ndarray:
        """Coefficients of the block whose label starts with ``label`` (e.g. ``'A[y1,y1]'``).

        Parameters
        ----------
        label : str
            The block's label, or its first word (``'B[y1,u1]'``).

        Raises
        ------
        KeyError
            If no block has that label.
        """
        for name, size, offset in self.dims[1:]:
            if name.split(' ')[0] == label or name == label:
                return self.data[offset : offset + size]
        raise KeyError(f'no block {label!r}; blocks: {[d[0] for d in self.dims[1:]]}')


def coefficient_layout(
    orders: Orders,
    theta: np.ndarray,
    output_names: Sequence[str] = (),
    input_names: Sequence[str] = (),
) -> CoefficientLayout:
    """Label the ARX parameter vector for a ``Float64MultiArray`` (pure function).

    Parameters
    ----------
    orders : Orders
        ARX orders (``nc``, ``nd``, ``nf`` zero).
    theta : array_like, shape (n_params,)
        Parameters in the layout of :mod:`.orders`.
    output_names, input_names : sequence of str
        Channel names (default ``y1 ..``, ``u1 ..``).

    Returns
    -------
    CoefficientLayout
        Dimensions and data (see :class:`CoefficientLayout`).
    """
    theta = np.asarray(theta, dtype=float).ravel()
    if theta.shape != (orders.n_params,):
        raise ValueError(f'theta must have {orders.n_params} values, got {theta.shape}')
    if np.any(orders.nc) or np.any(orders.nd) or np.any(orders.nf):
        raise ValueError('coefficient_layout describes ARX orders only (nc = nd = nf = 0)')
    ys = list(output_names) or [f'y{i + 1}' for i in range(orders.ny)]
    us = list(input_names) or [f'u{j + 1}' for j in range(orders.nu)]
    if len(ys) != orders.ny or len(us) != orders.nu:
        raise ValueError(
            f'names: {len(ys)} outputs and {len(us)} inputs given, the orders have '
            f'{orders.ny} and {orders.nu}'
        )
    dims = [('theta', orders.n_params, orders.n_params)]
    offset = 0
    for i in range(orders.ny):
        for j in range(orders.ny):
            n = int(orders.na[i, j])
            if n:
                dims.append((f'A[{ys[i]},{ys[j]}] na={n}', n, offset))
                offset += n
        for j in range(orders.nu):
            n = int(orders.nb[i, j])
            if n:
                dims.append((f'B[{ys[i]},{us[j]}] nb={n} nk={int(orders.nk[i, j])}', n, offset))
                offset += n
    return CoefficientLayout(tuple(dims), theta.copy())
