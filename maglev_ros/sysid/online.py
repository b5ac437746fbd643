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
their orders.  Pure functions, numpy and numba only (no rclpy).

Without a window, :meth:`OnlineArx.update` and :meth:`OnlineArx.update_many`
run one compiled kernel per call (history shift, regressor gather and
:func:`~.rls.rls_step` of every row): the numbers are bit for bit those of the
per-sample numpy code, at a few microseconds per sample.  The per-row ``P`` and
``theta`` are contiguous views into two flat buffers (``theta`` is the public
parameter vector as stored).  Numba's cache does not track the dependency on
:func:`~.rls.rls_step`: after editing it, clear ``__pycache__`` of this package.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from .model import PolyModel
from .orders import Orders, make_orders
from .rls import rls_step

__all__ = [
    'CoefficientLayout',
    'IdentifierStatus',
    'OnlineArx',
    'coefficient_layout',
    'load_kernels',
]


def _check(forgetting: float, p0: float, window: int | None, fit_window: int) -> None:
    if not 0.0 < forgetting <= 1.0:
        raise ValueError(f'forgetting factor must be in (0, 1], got {forgetting!r}')
    if not (np.isfinite(p0) and p0 > 0):
        raise ValueError(f'initial covariance must be > 0, got {p0!r}')
    if window is not None and (not isinstance(window, (int, np.integer)) or window < 1):
        raise ValueError(f'window must be a sample count >= 1 or None, got {window!r}')
    if not isinstance(fit_window, (int, np.integer)) or fit_window < 2:
        raise ValueError(f'fit_window must be a sample count >= 2, got {fit_window!r}')


@njit(cache=True)
def _advance(
    y: np.ndarray,
    u: np.ndarray,
    yh: np.ndarray,
    uh: np.ndarray,
    P: np.ndarray,
    theta: np.ndarray,
    layout: np.ndarray,
    index: np.ndarray,
    updates: np.ndarray,
    fit_y: np.ndarray,
    fit_e: np.ndarray,
    samples: int,
    lam: float,
    wait: bool,
    errors: np.ndarray,
) -> None:  # pragma: no cover - numba
    """One sample of :meth:`OnlineArx.update` in place (inputs already checked).

    Parameters
    ----------
    y : ndarray, shape (ny,)
        Outputs at ``t``, output units.
    u : ndarray, shape (nu,)
        Inputs at ``t``, input units.
    yh : ndarray, shape (ny, ylags)
        Output history, column 0 ``y(t-1)``; shifted in place.
    uh : ndarray, shape (nu, ulags)
        Input history, column 0 ``u(t)`` after the shift; shifted in place.
    P : ndarray, shape (sum of s_i**2,)
        Row covariances, row ``i`` the C-order ``(s_i, s_i)`` block at
        ``layout[0, i]``; updated in place.
    theta : ndarray, shape (n_params,)
        Parameters, row ``i`` at ``layout[1, i] : layout[1, i + 1]``; in place.
    layout : ndarray of int64, shape (3, ny + 1)
        Offsets of the ``P`` blocks, offsets of the ``theta`` (and ``index``)
        rows, first sample of each row (``orders.row_start``).
    index : ndarray of int64, shape (n_params,)
        Regressor positions in ``flat = [-yh.ravel(), uh.ravel()]``.
    updates : ndarray of int64, shape (ny,)
        Updates of each row, incremented in place.
    fit_y, fit_e : ndarray, shape (fit_window, ny)
        Fit buffers; slot ``samples % fit_window`` is written.
    samples : int
        Samples before this one.
    lam : float
        Forgetting factor.
    wait : bool
        Skip the rows whose regressor is not complete yet.
    errors : ndarray, shape (ny,)
        Output: a-priori prediction errors (NaN for a skipped row).
    """
    ny, ylags = yh.shape
    nu, ulags = uh.shape
    for j in range(nu):
        for k in range(ulags - 1, 0, -1):
            uh[j, k] = uh[j, k - 1]
        uh[j, 0] = u[j]
    nyl = ny * ylags
    for i in range(ny):
        errors[i] = np.nan
        if wait and samples < layout[2, i]:
            continue
        t0 = layout[1, i]
        s = layout[1, i + 1] - t0
        phi = np.empty(s)
        for a in range(s):
            k = index[t0 + a]
            if k < nyl:
                phi[a] = -yh[k // ylags, k % ylags]
            else:
                k -= nyl
                phi[a] = uh[k // ulags, k % ulags]
        p0 = layout[0, i]
        Pi = P[p0 : p0 + s * s].reshape((s, s))
        errors[i] = rls_step(Pi, theta[t0 : t0 + s], phi, y[i], lam)
        updates[i] += 1
    for j in range(ny):
        for k in range(ylags - 1, 0, -1):
            yh[j, k] = yh[j, k - 1]
        yh[j, 0] = y[j]
    slot = samples % fit_y.shape[0]
    for i in range(ny):
        fit_y[slot, i] = y[i]
        fit_e[slot, i] = errors[i]


@njit(cache=True)
def _all_finite(x: np.ndarray) -> bool:  # pragma: no cover - numba
    for v in x.ravel():
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True)
def _update_many(
    Y: np.ndarray,
    U: np.ndarray,
    yh: np.ndarray,
    uh: np.ndarray,
    P: np.ndarray,
    theta: np.ndarray,
    layout: np.ndarray,
    index: np.ndarray,
    updates: np.ndarray,
    fit_y: np.ndarray,
    fit_e: np.ndarray,
    samples: int,
    lam: float,
    wait: bool,
) -> np.ndarray:  # pragma: no cover - numba
    """Check all rows of ``Y`` (n, ny), ``U`` (n, nu), then add them; return the errors (n, ny).

    Any non-finite value: nothing is changed and an array of shape (0, ny) is
    returned.
    """
    if not (_all_finite(Y) and _all_finite(U)):
        return np.empty((0, yh.shape[0]))
    E = np.empty((Y.shape[0], yh.shape[0]))
    for r in range(Y.shape[0]):
        _advance(
            Y[r],
            U[r],
            yh,
            uh,
            P,
            theta,
            layout,
            index,
            updates,
            fit_y,
            fit_e,
            samples + r,
            lam,
            wait,
            E[r],
        )
    return E


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
        # the kernel's view of the rows: offsets into the flat P and theta buffers
        sizes = np.array(self._sizes, dtype=np.int64)
        self._layout = np.zeros((3, o.ny + 1), dtype=np.int64)
        self._layout[0, 1:] = np.cumsum(sizes**2)
        self._layout[1, 1:] = np.cumsum(sizes)
        self._layout[2, :-1] = self._starts
        self._index_flat = np.concatenate([np.zeros(0, np.int64), *self._index]).astype(np.int64)
        self._shapes = ((o.ny,), (o.nu,))
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Return to the initial state: ``theta = 0``, ``P = P0``, empty histories."""
        o = self.orders
        self._yh = np.zeros((o.ny, self._ylags))  # column 0: y(t-1)
        self._uh = np.zeros((o.nu, self._ulags))  # column 0: u(t)
        # flat buffers; the per-row P (s, s) and theta (s,) are contiguous views
        poff, toff = self._layout[0], self._layout[1]
        self._theta_flat = np.zeros(int(toff[-1]))
        self._P_flat = np.zeros(int(poff[-1]))
        self._theta = [self._theta_flat[toff[i] : toff[i + 1]] for i in range(o.ny)]
        self._P = [
            self._P_flat[poff[i] : poff[i + 1]].reshape(s, s) for i, s in enumerate(self._sizes)
        ]
        for P, s in zip(self._P, self._sizes, strict=True):
            P[...] = self.initial_covariance * np.eye(s)
        self.samples = 0
        self._updates = np.zeros(o.ny, dtype=np.int64)
        self._last_error = np.full(o.ny, np.nan)
        self._fit_y = np.full((self.fit_window, o.ny), np.nan)
        self._fit_e = np.full((self.fit_window, o.ny), np.nan)
        self._window: list[deque[tuple[np.ndarray, float]]] = [deque() for _ in range(o.ny)]
        self._theta_prev: np.ndarray | None = None
        # the state arguments of the kernels, in their order
        self._state = (
            self._yh,
            self._uh,
            self._P_flat,
            self._theta_flat,
            self._layout,
            self._index_flat,
            self._updates,
            self._fit_y,
            self._fit_e,
        )

    @property
    def theta(self) -> np.ndarray:
        """Current parameters, shape (n_params,) (layout of :mod:`.orders`; a copy)."""
        return self._theta_flat.copy()

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
        y = np.ascontiguousarray(y, dtype=float)  # ndim >= 1, as np.atleast_1d
        u = np.ascontiguousarray(u, dtype=float)
        if y.shape != self._shapes[0] or u.shape != self._shapes[1]:
            raise self._shape_error(y.shape, u.shape)
        if self.window is not None:
            if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
                raise self._finite_error(y, u)
            return self._update_window(y, u)
        E = _update_many(  # a burst of one: the same compiled step as update_many
            y[None], u[None], *self._state, self.samples, self.forgetting, self.wait_for_history
        )
        if E.shape[0] == 0:
            raise self._finite_error(y, u)
        errors = E[0]
        self._last_error = errors
        self.samples += 1
        return errors

    def update_many(
        self, Y: Sequence[Sequence[float]] | np.ndarray, U: Sequence[Sequence[float]] | np.ndarray
    ) -> np.ndarray:
        """Add ``n`` samples at once; the same as :meth:`update` row by row.

        The estimate, the histories, the fit buffers, :attr:`samples` and the
        last prediction error end exactly (bit for bit) as after ``n`` calls
        of :meth:`update`, in one compiled call.

        Parameters
        ----------
        Y : array_like, shape (n, ny)
            Outputs at ``t .. t+n-1``, output units.
        U : array_like, shape (n, nu)
            Inputs at ``t .. t+n-1``, input units.

        Returns
        -------
        ndarray, shape (n, ny)
            The a-priori prediction errors of each sample (as :meth:`update`).

        Raises
        ------
        ValueError
            Wrong shapes or a non-finite value in any row: no sample is added
            (the state is left unchanged, also for the rows before it).
        """
        ny, nu = self._shapes[0][0], self._shapes[1][0]
        Y = np.ascontiguousarray(Y, dtype=float)
        U = np.ascontiguousarray(U, dtype=float)
        if Y.ndim != 2 or Y.shape[1] != ny or U.shape != (Y.shape[0], nu):
            raise ValueError(
                f'update_many needs Y of shape (n, {ny}) and U of shape (n, {nu}), '
                f'got {Y.shape} and {U.shape}'
            )
        if self.window is not None:
            bad = self._first_nonfinite(Y, U)
            if bad is not None:
                raise self._finite_error(Y[bad], U[bad], bad)
            E = np.empty((Y.shape[0], ny))
            for r in range(Y.shape[0]):
                E[r] = self._update_window(Y[r], U[r])
            return E
        if Y.shape[0] == 0:
            return np.empty((0, ny))
        E = _update_many(Y, U, *self._state, self.samples, self.forgetting, self.wait_for_history)
        if E.shape[0] == 0:
            bad = self._first_nonfinite(Y, U)
            raise self._finite_error(Y[bad], U[bad], bad)
        self._last_error = E[-1].copy()
        self.samples += Y.shape[0]
        return E

    @staticmethod
    def _first_nonfinite(Y: np.ndarray, U: np.ndarray) -> int | None:
        """Index of the first row of ``Y`` (n, ny) or ``U`` (n, nu) with a non-finite value."""
        ok = np.isfinite(Y).all(axis=1) & np.isfinite(U).all(axis=1)
        return None if ok.all() else int(np.argmin(ok))

    def _shape_error(self, y_shape: tuple[int, ...], u_shape: tuple[int, ...]) -> ValueError:
        o = self.orders
        return ValueError(
            f'update needs y of shape ({o.ny},) and u of shape ({o.nu},), '
            f'got {y_shape} and {u_shape}'
        )

    @staticmethod
    def _finite_error(y: np.ndarray, u: np.ndarray, row: int | None = None) -> ValueError:
        where = '' if row is None else f' (row {row})'
        return ValueError(f'samples must be finite, got y={y.tolist()} u={u.tolist()}{where}')

    def _update_window(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """:meth:`update` with a sliding window (numpy; ``y`` (ny,), ``u`` (nu,) checked)."""
        o = self.orders
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


def load_kernels() -> None:
    """Load (or compile) the compiled update kernel now, with a throwaway estimate.

    Loading takes 0.3 to 1.5 s holding the GIL: a process with a real-time
    loop in another thread calls this before the loop runs, not with its first
    sample.
    """
    OnlineArx(1, 1).update_many(np.zeros((2, 1)), np.zeros((2, 1)))
