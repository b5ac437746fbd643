"""Identified polynomial models: simulation, prediction, poles, frequency response, text.

:class:`PolyModel` covers ARX, IV, ARMAX, OE and BJ structures (see
:mod:`maglev_ros.sysid.orders` for the conventions).  Simulation and prediction
run on the (possibly non-minimal) innovations state-space form produced by
:func:`~maglev_ros.sysid.polynomial.innovations_form`, compiled with numba.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import lfilter

from .dataset import IdData
from .orders import Orders
from .polynomial import (
    Polynomials,
    free_response,
    innovations_form,
    predictor_errors,
    simulate_ss,
    unpack,
)

__all__ = ['DivergenceError', 'EstimationReport', 'PolyModel']


class DivergenceError(ValueError):
    """A model's simulation or predictor grew beyond floating point (unstable poles)."""


def _initial_state_fit(basis: np.ndarray, target: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """Least-squares initial state ``x0`` of ``basis @ x0 ~ target``.

    Refuses non-finite systems before LAPACK sees them: ``gelsd`` would print
    ``On entry to DLASCL parameter number 4 had an illegal value`` on stdout
    (Fortran runtime) and fail with ``SVD did not converge``.
    """
    if not (np.all(np.isfinite(basis)) and np.all(np.isfinite(target))):
        worst = float(np.max(np.abs(poles))) if len(poles) else float('nan')
        raise DivergenceError(
            f'the model diverges (largest pole magnitude {worst:.3g}): '
            'no initial state can be fitted'
        )
    return np.linalg.lstsq(basis, target, rcond=None)[0]


STRUCTURE_TITLES = {
    'arx': ('ARX', 'A(z)y(t) = B(z)u(t) + e(t)'),
    'iv4': ('ARX (instrumental variables)', 'A(z)y(t) = B(z)u(t) + e(t)'),
    'armax': ('ARMAX', 'A(z)y(t) = B(z)u(t) + C(z)e(t)'),
    'oe': ('OE', 'y(t) = [B(z)/F(z)]u(t) + e(t)'),
    'bj': ('BJ', 'y(t) = [B(z)/F(z)]u(t) + [C(z)/D(z)]e(t)'),
}


@dataclass(frozen=True)
class EstimationReport:
    """How a model was estimated and how well it fits its estimation data.

    Attributes
    ----------
    method : str
        Estimator and numerical method.
    n_samples : int
        Number of estimation samples used.
    fit : ndarray, shape (ny,)
        One-step-prediction fit in percent on the estimation data.
    mse : ndarray, shape (ny,)
        Mean squared prediction error per output, in output units squared.
    fpe : float
        Final prediction error.
    aic : float
        Akaike's information criterion.
    iterations : int
        Iterations of an iterative method (0 for direct solutions).
    converged : bool
        False if an iterative method stopped at its cap ``max_iter`` while the
        loss was still decreasing.
    max_iter : int
        The iteration cap (0 for direct solutions).
    """

    method: str
    n_samples: int
    fit: np.ndarray
    mse: np.ndarray
    fpe: float
    aic: float
    iterations: int = 0
    converged: bool = True
    max_iter: int = 0


def _poly_text(coeffs: np.ndarray, monic: bool, first_lag: int = 0) -> str:
    terms = []
    for lag, c in enumerate(coeffs):
        if c == 0 and not (lag == 0 and monic):
            continue
        lag_txt = '' if lag == 0 else (' z^-1' if lag == 1 else f' z^-{lag}')
        mag = abs(c)
        coef = '' if (np.isclose(mag, 1.0) and lag > 0) else f'{mag:.4g}'
        body = (coef + lag_txt).strip() if lag else f'{mag:.4g}'
        if not terms:
            terms.append(('-' if c < 0 else '') + body)
        else:
            terms.append(('- ' if c < 0 else '+ ') + body)
    return ' '.join(terms) if terms else '0'


@dataclass(frozen=True, eq=False)
class PolyModel:
    """A discrete-time polynomial model ``A y = B/F u + C/D e``.

    Parameters
    ----------
    structure : {'arx', 'iv4', 'armax', 'oe', 'bj'}
        Model structure (how it was estimated).
    orders : Orders
        Order matrices.
    theta : ndarray, shape (n_params,)
        Parameter vector (layout in :mod:`maglev_ros.sysid.orders`).
    Ts : float
        Sample time in seconds.
    noise_variance : ndarray, shape (ny, ny)
        Innovations covariance.
    covariance : ndarray, shape (n_params, n_params) or None
        Parameter covariance.
    output_names, input_names, output_units, input_units : tuple of str
        Channel labels.
    report : EstimationReport or None
        Estimation summary.
    """

    structure: str
    orders: Orders
    theta: np.ndarray
    Ts: float
    noise_variance: np.ndarray
    covariance: np.ndarray | None = None
    output_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    output_units: tuple[str, ...] = ()
    input_units: tuple[str, ...] = ()
    report: EstimationReport | None = None
    _polys: Polynomials = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.structure not in STRUCTURE_TITLES:
            raise ValueError(
                f'structure must be one of {sorted(STRUCTURE_TITLES)}, got {self.structure!r}'
            )
        if not self.Ts > 0:
            raise ValueError(f'Ts must be > 0 seconds, got {self.Ts!r}')
        theta = np.asarray(self.theta, dtype=float).copy()
        object.__setattr__(self, 'theta', theta)
        object.__setattr__(self, '_polys', unpack(self.orders, theta))
        ny, nu = self.ny, self.nu
        for name, count, prefix in (('output_names', ny, 'y'), ('input_names', nu, 'u')):
            if not getattr(self, name):
                object.__setattr__(self, name, tuple(f'{prefix}{i + 1}' for i in range(count)))
        for name, count in (('output_units', ny), ('input_units', nu)):
            if not getattr(self, name):
                object.__setattr__(self, name, ('',) * count)
        object.__setattr__(
            self, 'noise_variance', np.atleast_2d(np.asarray(self.noise_variance, dtype=float))
        )

    # --------------------------------------------------------------- accessors
    @property
    def ny(self) -> int:
        """Number of outputs."""
        return self.orders.ny

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return self.orders.nu

    @property
    def A(self) -> np.ndarray:  # noqa: N802 - toolbox polynomial name
        """``A`` coefficients, shape (ny, ny, 1 + max na), index ``[i, j, lag]``."""
        return self._polys[0]

    @property
    def B(self) -> np.ndarray:  # noqa: N802 - toolbox polynomial name
        """``B`` coefficients, shape (ny, nu, max(nk + nb)), index ``[i, j, lag]``."""
        return self._polys[1]

    @property
    def C(self) -> np.ndarray:  # noqa: N802 - toolbox polynomial name
        """``C`` coefficients, shape (ny, 1 + max nc)."""
        return self._polys[2]

    @property
    def D(self) -> np.ndarray:  # noqa: N802 - toolbox polynomial name
        """``D`` coefficients, shape (ny, 1 + max nd)."""
        return self._polys[3]

    @property
    def F(self) -> np.ndarray:  # noqa: N802 - toolbox polynomial name
        """``F`` coefficients, shape (ny, nu, 1 + max nf)."""
        return self._polys[4]

    @property
    def std(self) -> np.ndarray | None:
        """Standard deviations of the parameters, shape (n_params,), or None."""
        if self.covariance is None:
            return None
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def polynomial(self, name: str, i: int = 0, j: int = 0) -> np.ndarray:
        """Return one polynomial trimmed to its order, coefficients of ``q^0, q^-1, ...``.

        Parameters
        ----------
        name : {'A', 'B', 'C', 'D', 'F'}
            Polynomial.
        i, j : int
            Output and input (or second output for ``A``) index, 0-based.

        Returns
        -------
        ndarray
            Coefficients (``B`` includes the ``nk`` leading zeros).
        """
        o = self.orders
        if name == 'A':
            return self.A[i, j, : o.na[i, j] + 1].copy()
        if name == 'B':
            return self.B[i, j, : o.nk[i, j] + o.nb[i, j]].copy()
        if name == 'C':
            return self.C[i, : o.nc[i] + 1].copy()
        if name == 'D':
            return self.D[i, : o.nd[i] + 1].copy()
        if name == 'F':
            return self.F[i, j, : o.nf[i, j] + 1].copy()
        raise ValueError(f"polynomial name must be one of 'ABCDF', got {name!r}")

    # ------------------------------------------------------------- simulation
    def _inputs(self, data: IdData | np.ndarray) -> np.ndarray:
        u = data.u if isinstance(data, IdData) else np.asarray(data, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[1] != self.nu:
            raise ValueError(f'input must have shape (N, {self.nu}), got {u.shape}')
        return np.asarray(u, dtype=float)

    def _outputs(self, data: IdData) -> np.ndarray:
        if not isinstance(data, IdData):
            raise TypeError(f'data must be IdData, got {type(data).__name__}')
        if data.ny != self.ny or data.nu != self.nu:
            raise ValueError(
                f'data has ny={data.ny}, nu={data.nu}; model has ny={self.ny}, nu={self.nu}'
            )
        return np.asarray(data.y, dtype=float)

    def innovations_form(self) -> tuple[np.ndarray, ...]:
        """Return ``(A, B, C, D, K)`` of ``x+ = Ax + Bu + Ke``, ``y = Cx + Du + e``."""
        return innovations_form(self._polys)

    def simulate(self, data: IdData | np.ndarray, ic: str = 'zero') -> np.ndarray:
        """Simulate the noise-free response to the inputs.

        Parameters
        ----------
        data : IdData or ndarray, shape (N, nu)
            Inputs (and, for ``ic='estimate'``, outputs).
        ic : {'zero', 'estimate'}
            Initial conditions: zero, or least-squares estimated from the
            measured outputs (needs an :class:`IdData`).

        Returns
        -------
        ndarray, shape (N, ny)
            Simulated outputs.

        Raises
        ------
        DivergenceError
            With ``ic='estimate'``, if the simulation of an unstable model
            overflows (no initial state can be fitted).
        """
        if ic not in ('zero', 'estimate'):
            raise ValueError(f"ic must be 'zero' or 'estimate', got {ic!r}")
        u = self._inputs(data)
        if self._coupled:
            A, B, C, D, _ = innovations_form(self._polys, noise=False)
            ysim = simulate_ss(A, B, C, D, np.zeros(A.shape[0]), np.ascontiguousarray(u))
        else:  # one rational filter per channel (scipy lfilter), channel rows
            ur = np.ascontiguousarray(u.T)
            rows = np.zeros((self.ny, u.shape[0]))
            for i in range(self.ny):
                a = self.polynomial('A', i, i)
                for j in range(self.nu):
                    if self.orders.nb[i, j]:
                        rows[i] += lfilter(
                            self.polynomial('B', i, j),
                            np.convolve(a, self.polynomial('F', i, j)),
                            ur[j],
                        )
            ysim = rows.T
        if ic == 'zero':
            return ysim
        A, B, C, D, _ = innovations_form(self._polys, noise=False)
        if A.shape[0] == 0:
            return ysim
        if not isinstance(data, IdData):
            raise TypeError("ic='estimate' needs IdData with measured outputs")
        y = self._outputs(data)
        basis = free_response(A, C, y.shape[0]).reshape(-1, A.shape[0])
        x0 = _initial_state_fit(basis, (y - ysim).ravel(), np.linalg.eigvals(A))
        return ysim + (basis @ x0).reshape(y.shape)

    @property
    def _coupled(self) -> bool:
        """True if some ``A_ij`` with ``i != j`` is present (outputs interact)."""
        return bool(np.any(self.orders.na[~np.eye(self.ny, dtype=bool)]))

    def _filter_residuals(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Zero-initial-state ``e_i = D_i/C_i (sum_j A_ij y_j - sum_j B_ij/F_ij u_j)``."""
        o = self.orders
        N = y.shape[0]
        yr = np.ascontiguousarray(y.T)  # channel rows (free for IdData, which is channel-major)
        ur = np.ascontiguousarray(u.T)
        e = np.empty((self.ny, N))
        for i in range(self.ny):
            v = yr[i].copy()
            for j in range(self.ny):
                if o.na[i, j]:
                    a = self.polynomial('A', i, j)
                    a[0] = 0.0
                    v += np.convolve(yr[j], a)[:N]
            for j in range(self.nu):
                if o.nb[i, j]:
                    b = self.polynomial('B', i, j)
                    if o.nf[i, j]:
                        v -= lfilter(b, self.polynomial('F', i, j), ur[j])
                    else:
                        v -= np.convolve(ur[j], b)[:N]
            if o.nc[i] or o.nd[i]:
                v = lfilter(self.polynomial('D', i), self.polynomial('C', i), v)
            e[i] = v
        return e.T

    def residuals(self, data: IdData, ic: str = 'zero') -> np.ndarray:
        """One-step prediction errors (the innovations) on ``data``, shape (N, ny).

        Parameters
        ----------
        data : IdData
            Input/output data.
        ic : {'zero', 'estimate'}
            Initial state of the predictor: zero or least-squares estimated.

        Returns
        -------
        ndarray, shape (N, ny)
            Prediction errors in output units.
        """
        if ic not in ('zero', 'estimate'):
            raise ValueError(f"ic must be 'zero' or 'estimate', got {ic!r}")
        y = self._outputs(data)
        u = self._inputs(data)
        e = self._filter_residuals(y, u)
        if ic == 'zero':
            return e
        A, B, C, D, K = self.innovations_form()
        if A.shape[0] == 0:
            return e
        basis = free_response(A - K @ C, C, y.shape[0]).reshape(-1, A.shape[0])
        x0 = _initial_state_fit(basis, e.ravel(), np.linalg.eigvals(A - K @ C))
        return e - (basis @ x0).reshape(e.shape)

    def residuals_state_space(self, data: IdData) -> np.ndarray:
        """Prediction errors from the innovations-form Kalman predictor (zero state), (N, ny).

        Equal to :meth:`residuals` with ``ic='zero'``; kept as an independent
        cross-check of the polynomial filters.

        Parameters
        ----------
        data : IdData
            The data set.
        """
        A, B, C, D, K = self.innovations_form()
        return predictor_errors(
            A,
            B,
            C,
            D,
            K,
            np.zeros(A.shape[0]),
            np.ascontiguousarray(self._inputs(data)),
            np.ascontiguousarray(self._outputs(data)),
        )

    def predict(self, data: IdData, k: int = 1, ic: str = 'zero') -> np.ndarray:
        """Predict the outputs ``k`` steps ahead, ``yhat(t | t-k)``.

        Parameters
        ----------
        data : IdData
            Input/output data.
        k : int
            Prediction horizon in samples, >= 1.
        ic : {'zero', 'estimate'}
            Initial state of the predictor.

        Returns
        -------
        ndarray, shape (N, ny)
            Predicted outputs.
        """
        if int(k) < 1:
            raise ValueError(f'prediction horizon k must be >= 1, got {k!r}')
        e = self.residuals(data, ic=ic)
        yhat = data.y - e
        if k == 1:
            return yhat
        A, _, C, _, K = self.innovations_form()
        M = K.copy()
        for i in range(1, int(k)):
            h = C @ M
            yhat[i:] -= e[:-i] @ h.T
            M = A @ M
        return yhat

    # -------------------------------------------------------------- analysis
    def poles(self) -> np.ndarray:
        """Poles of the input-output model (roots of ``det A`` and of all ``F_ij``) in z."""
        A, _, _, _, F = self._polys
        ny = self.ny
        o = self.orders
        out = []
        if np.any(o.na[~np.eye(ny, dtype=bool)]):
            Ae = A[:, :, 1:]
            deg = Ae.shape[2]
            comp = np.zeros((ny * deg, ny * deg))
            for k in range(deg):
                comp[k * ny : (k + 1) * ny, :ny] = -Ae[:, :, k]
                if k + 1 < deg:
                    comp[k * ny : (k + 1) * ny, (k + 1) * ny : (k + 2) * ny] = np.eye(ny)
            out.append(np.linalg.eigvals(comp))
        else:
            out += [np.roots(self.polynomial('A', i, i)) for i in range(ny)]
        out += [np.roots(self.polynomial('F', i, j)) for i in range(ny) for j in range(self.nu)]
        return np.concatenate(out) if out else np.zeros(0, dtype=complex)

    def zeros(self, output: int = 0, input: int = 0) -> np.ndarray:  # noqa: A002
        """Zeros (in z) of the numerator ``B_ij`` of one input-output channel.

        Parameters
        ----------
        output : int
            Output index.
        input : int
            Input index.
        """
        b = np.trim_zeros(self.polynomial('B', output, input), 'f')
        return np.roots(b) if len(b) > 1 else np.zeros(0, dtype=complex)

    @property
    def is_stable(self) -> bool:
        """True if all poles are strictly inside the unit circle."""
        p = self.poles()
        return bool(np.all(np.abs(p) < 1.0))

    def freqresp(self, f: np.ndarray) -> np.ndarray:
        """Frequency response ``G(e^{j 2 pi f Ts})`` of ``u -> y``.

        Parameters
        ----------
        f : array_like, shape (nf,)
            Frequencies in Hz.

        Returns
        -------
        ndarray, shape (nf, ny, nu), complex
            Response matrices.
        """
        f = np.atleast_1d(np.asarray(f, dtype=float))
        A, B, _, _, F = self._polys
        zinv = np.exp(-2j * np.pi * f * self.Ts)

        def evaluate(p: np.ndarray) -> np.ndarray:
            powers = zinv[:, None] ** np.arange(p.shape[-1])[None, :]
            return np.einsum('...k,fk->f...', p, powers)

        Az = evaluate(A)
        Bz = evaluate(B) / evaluate(F)
        return np.linalg.solve(Az, Bz)

    def to_ss(self, noise: bool = False):  # noqa: ANN201 - control type
        """Convert to a python-control discrete ``StateSpace`` (dt = Ts).

        Parameters
        ----------
        noise : bool
            If True, the inputs are ``[u, e]`` with ``e`` the normalized
            innovations (unit variance); otherwise only ``u -> y``.

        Returns
        -------
        control.StateSpace
            Discrete-time state-space model (may be non-minimal).
        """
        import control

        A, B, C, D, K = innovations_form(self._polys, noise=noise)
        if noise:
            L = np.linalg.cholesky(self.noise_variance + 1e-300 * np.eye(self.ny))
            B = np.hstack([B, K @ L])
            D = np.hstack([D, L])
        if A.shape[0] == 0:
            return control.ss([], [], [], D, dt=self.Ts)
        return control.ss(A, B, C, D, dt=self.Ts)

    def to_tf(self):  # noqa: ANN201 - control type
        """Convert ``u -> y`` to a python-control discrete ``TransferFunction`` (dt = Ts).

        Returns
        -------
        control.TransferFunction
            ``ny x nu`` transfer function in z; cross-coupled ``A`` is handled
            with ``G = adj(A) B / det(A)``.
        """
        import control

        ny, nu = self.ny, self.nu
        nums, dens = [], []
        if np.any(self.orders.nf):  # F only with diagonal A: G_ij = B_ij / (A_ii F_ij)
            for i in range(ny):
                nums.append([self.polynomial('B', i, j) for j in range(nu)])
                dens.append(
                    [
                        np.convolve(self.polynomial('A', i, i), self.polynomial('F', i, j))
                        for j in range(nu)
                    ]
                )
        else:
            Apoly = [[self.polynomial('A', i, j) for j in range(ny)] for i in range(ny)]
            det = _poly_det(Apoly)
            for i in range(ny):
                row = []
                for j in range(nu):
                    num = np.zeros(1)
                    for m in range(ny):
                        num = _padd(
                            num, np.convolve(_cofactor(Apoly, m, i), self.polynomial('B', m, j))
                        )
                    row.append(num)
                nums.append(row)
                dens.append([det] * nu)
        for i in range(ny):
            for j in range(nu):
                num, den = nums[i][j], dens[i][j]
                length = max(len(num), len(den))
                nums[i][j] = np.pad(num, (0, length - len(num)))
                dens[i][j] = np.pad(den, (0, length - len(den)))
        return control.tf(nums, dens, dt=self.Ts)

    # ------------------------------------------------------------------ text
    def __str__(self) -> str:
        title, equation = STRUCTURE_TITLES[self.structure]
        o = self.orders
        std = self.std
        lines = [f'Discrete-time {title} model:  {equation}']
        if self.ny > 1 or self.nu > 1:
            lines[0] = f'Discrete-time {title} model ({self.ny} outputs, {self.nu} inputs)'
        lines.append('  Polynomials in z^-1 (z^-1 = one-sample delay):')
        pos = 0
        for i in range(self.ny):
            if self.ny > 1:
                lines.append(f'  Output {self.output_names[i]}:')
            entries: list[tuple[str, np.ndarray, bool, int, int]] = []
            for j in range(self.ny):
                if o.na[i, j] or (i == j and self.structure in ('arx', 'iv4', 'armax')):
                    name = f'A{i + 1}{j + 1}' if self.ny > 1 else 'A'
                    entries.append((name, self.polynomial('A', i, j), i == j, o.na[i, j], pos))
                pos += o.na[i, j]
            for j in range(self.nu):
                name = f'B{i + 1}{j + 1}' if self.ny * self.nu > 1 else 'B'
                entries.append((name, self.polynomial('B', i, j), False, o.nb[i, j], pos))
                pos += o.nb[i, j]
            for key, n in (('C', o.nc[i]), ('D', o.nd[i])):
                if n or (key == 'C' and self.structure in ('armax', 'bj')):
                    name = f'{key}{i + 1}' if self.ny > 1 else key
                    entries.append((name, self.polynomial(key, i), True, n, pos))
                pos += n
            for j in range(self.nu):
                if o.nf[i, j]:
                    name = f'F{i + 1}{j + 1}' if self.ny * self.nu > 1 else 'F'
                    entries.append((name, self.polynomial('F', i, j), True, o.nf[i, j], pos))
                pos += o.nf[i, j]
            for name, poly, monic, n, start in entries:
                lines.append(f'    {name}(z) = {_poly_text(poly, monic)}')
                if std is not None and n:
                    s = std[start : start + n]
                    lines.append('      std: ' + ' '.join(f'{v:.3g}' for v in s))
        lines.append(f'  Orders: {o.describe()}')
        lines.append(f'  Number of free coefficients: {o.n_params}')
        lines.append(f'  Sample time: {self.Ts:g} seconds')
        if self.report is not None:
            r = self.report
            fits = ', '.join(f'{f:.2f}%' for f in r.fit)
            mses = ', '.join(f'{m:.4g}' for m in r.mse)
            lines.append(
                f'  Estimated with {r.method} on {r.n_samples} samples'
                + (f', {r.iterations} iterations' if r.iterations else '')
                + '.'
            )
            if not r.converged:
                lines.append(
                    f'  Stopped at the iteration cap ({r.max_iter}) before converging: '
                    'raise it (max_iter, --max-iter).'
                )
            lines.append(f'  Fit to estimation data: {fits} (prediction focus)')
            lines.append(f'  FPE: {r.fpe:.4g}, MSE: {mses}')
        return '\n'.join(lines)


def _padd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    n = max(len(a), len(b))
    return np.pad(a, (0, n - len(a))) + np.pad(b, (0, n - len(b)))


def _minor(M: list[list[np.ndarray]], row: int, col: int) -> list[list[np.ndarray]]:
    return [[M[i][j] for j in range(len(M)) if j != col] for i in range(len(M)) if i != row]


def _poly_det(M: list[list[np.ndarray]]) -> np.ndarray:
    n = len(M)
    if n == 1:
        return np.asarray(M[0][0], dtype=float)
    total = np.zeros(1)
    for j in range(n):
        term = np.convolve(M[0][j], _poly_det(_minor(M, 0, j)))
        total = _padd(total, term if j % 2 == 0 else -term)
    return total


def _cofactor(M: list[list[np.ndarray]], row: int, col: int) -> np.ndarray:
    if len(M) == 1:
        return np.ones(1)
    c = _poly_det(_minor(M, row, col))
    return c if (row + col) % 2 == 0 else -c
