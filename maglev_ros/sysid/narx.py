"""Polynomial nonlinear ARX (NARX) models: regressors, FROLS structure selection, simulation.

Output ``i`` of a NARX model is a sum of monomials of lagged signals,

``y_i(t) = sum_k theta_ik prod_m x_m(t)^p_km + e_i(t)``,

with the variables ``x`` the lagged outputs ``y_j(t-1) .. y_j(t-na)`` of every
output ``j`` and the lagged inputs ``u_j(t-nk) .. u_j(t-nk-nb+1)`` of every
input, and the monomials of total degree 0 (a constant) to ``degree``.  The
candidates are shared by all outputs (MIMO); each output gets its own
selection by :func:`~maglev_ros.sysid.frols.frols` (one FROLS per output), so
a 2-output model may use different terms for each output.

Several experiments (a sequence of :class:`~maglev_ros.sysid.IdData`) are
stacked row-wise, each with its own first ``max lag`` samples dropped, so no
regressor mixes samples across an experiment's boundary.

Simulation and k-step prediction are compiled with numba.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numba
import numpy as np

from .criteria import fit_percent
from .dataset import IdData, as_experiments
from .frols import frols
from .model import EstimationReport

__all__ = ['NarxModel', 'NarxStructure', 'narx']


@dataclass(frozen=True)
class NarxStructure:
    """Lags, channels and the candidate monomials of a polynomial NARX model.

    Parameters
    ----------
    ny, nu : int
        Numbers of outputs and inputs.
    na : int
        Output lags ``1..na`` (samples).
    nb : int
        Number of input lags, ``nk..nk+nb-1`` (samples).
    nk : int
        Input delay in samples (>= 0).
    degree : int
        Largest total degree of a monomial (>= 1).
    """

    ny: int
    nu: int
    na: int
    nb: int
    nk: int
    degree: int
    variables: tuple[tuple[int, int, int], ...] = field(init=False, repr=False)
    monomials: tuple[tuple[int, ...], ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for name in ('ny', 'na', 'degree'):
            if int(getattr(self, name)) < 1:
                raise ValueError(f'{name} must be >= 1, got {getattr(self, name)!r}')
        for name in ('nu', 'nb', 'nk'):
            if int(getattr(self, name)) < 0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)!r}')
        variables = [(0, j, lag) for j in range(self.ny) for lag in range(1, self.na + 1)]
        variables += [
            (1, j, lag) for j in range(self.nu) for lag in range(self.nk, self.nk + self.nb)
        ]
        monomials: list[tuple[int, ...]] = [()]
        for d in range(1, self.degree + 1):
            monomials += list(itertools.combinations_with_replacement(range(len(variables)), d))
        object.__setattr__(self, 'variables', tuple(variables))
        object.__setattr__(self, 'monomials', tuple(monomials))

    @property
    def max_lag(self) -> int:
        """Samples of history a regressor row needs."""
        return max(self.na, self.nk + self.nb - 1 if self.nb else 0)

    def variable_name(
        self, v: int, output_names: Sequence[str], input_names: Sequence[str]
    ) -> str:
        """Text of variable ``v``, e.g. ``y1(t-2)``.

        Parameters
        ----------
        v : int
            Index into ``variables`` (the lagged outputs, then the lagged inputs).
        output_names : sequence of str
            Names of the outputs, indexed by channel.
        input_names : sequence of str
            Names of the inputs, indexed by channel.
        """
        kind, j, lag = self.variables[v]
        name = (output_names if kind == 0 else input_names)[j]
        return f'{name}(t-{lag})' if lag else f'{name}(t)'

    def term_name(self, term: int, output_names: Sequence[str], input_names: Sequence[str]) -> str:
        """Text of candidate monomial ``term``, e.g. ``y1(t-1)*u1(t-1)`` or ``1``.

        Parameters
        ----------
        term : int
            Index into ``monomials`` (0 the constant).
        output_names : sequence of str
            Names of the outputs, indexed by channel.
        input_names : sequence of str
            Names of the inputs, indexed by channel.
        """
        parts = self.monomials[term]
        if not parts:
            return '1'
        out = []
        for v, group in itertools.groupby(parts):
            power = len(list(group))
            name = self.variable_name(v, output_names, input_names)
            out.append(name if power == 1 else f'{name}^{power}')
        return '*'.join(out)

    def candidates(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Candidate regressor matrix of one experiment, rows ``t = max_lag .. N-1``.

        Parameters
        ----------
        y : ndarray, shape (N, ny)
            Outputs.
        u : ndarray, shape (N, nu)
            Inputs.

        Returns
        -------
        ndarray, shape (N - max_lag, n_candidates)
            One column per monomial (the constant first).
        """
        N = y.shape[0]
        start = self.max_lag
        cols = [
            (y if kind == 0 else u)[start - lag : N - lag, j] for kind, j, lag in self.variables
        ]
        out = np.empty((N - start, len(self.monomials)))
        for k, parts in enumerate(self.monomials):
            col = np.ones(N - start)
            for v in parts:
                col = col * cols[v]
            out[:, k] = col
        return out

    def term_arrays(self, terms: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
        """Flat arrays for the compiled simulator.

        Parameters
        ----------
        terms : sequence of ndarray of int
            Selected candidate monomials (indices into ``monomials``), one array
            per output.

        Returns
        -------
        kind, channel, lag, factors, owner : ndarray of int
            ``(kind, channel, lag)`` of the variables, shapes (n_variables,);
            ``factors`` (n_terms, degree) variable indices padded with -1, and
            ``owner`` (n_terms,) the output of each term.
        """
        kinds = np.array([v[0] for v in self.variables], dtype=np.int64)
        chans = np.array([v[1] for v in self.variables], dtype=np.int64)
        lags = np.array([v[2] for v in self.variables], dtype=np.int64)
        flat = [(i, int(t)) for i, ts in enumerate(terms) for t in ts]
        factors = -np.ones((len(flat), self.degree), dtype=np.int64)
        owner = np.zeros(len(flat), dtype=np.int64)
        for row, (i, t) in enumerate(flat):
            parts = self.monomials[t]
            factors[row, : len(parts)] = parts
            owner[row] = i
        return kinds, chans, lags, factors, owner


@numba.njit(cache=True)
def _term_value(t, row, factors, kinds, chans, lags, y, u):  # pragma: no cover - compiled
    value = 1.0
    for m in range(factors.shape[1]):
        v = factors[row, m]
        if v < 0:
            break
        if kinds[v] == 0:
            value *= y[t - lags[v], chans[v]]
        else:
            value *= u[t - lags[v], chans[v]]
    return value


@numba.njit(cache=True)
def _simulate(y, u, start, kinds, chans, lags, factors, owner, theta):  # pragma: no cover
    """Free-run from ``start``: ``y[t]`` for ``t >= start`` from the model's own past."""
    N, ny = y.shape
    for t in range(start, N):
        for i in range(ny):
            y[t, i] = 0.0
        for row in range(factors.shape[0]):
            y[t, owner[row]] += theta[row] * _term_value(t, row, factors, kinds, chans, lags, y, u)
        for i in range(ny):
            if not np.isfinite(y[t, i]) or abs(y[t, i]) > 1e150:
                return t
    return N


@numba.njit(cache=True)
def _predict(y, u, k, start, kinds, chans, lags, factors, owner, theta, out):  # pragma: no cover
    """``out[t] = yhat(t | t-k)``: k model steps from the measured outputs up to ``t-k``."""
    N, ny = y.shape
    depth = 0
    for v in range(lags.shape[0]):
        depth = max(depth, lags[v])
    buf = np.zeros((depth + k, ny))
    ubuf = np.zeros((depth + k, u.shape[1]))
    for t in range(start + k - 1, N):
        t0 = t - k + 1  # first predicted sample
        for s in range(depth):
            buf[s] = y[t0 - depth + s]
        for s in range(depth + k):
            ubuf[s] = u[t0 - depth + s]
        for s in range(depth, depth + k):
            for i in range(ny):
                buf[s, i] = 0.0
            for row in range(factors.shape[0]):
                buf[s, owner[row]] += theta[row] * _term_value(
                    s, row, factors, kinds, chans, lags, buf, ubuf
                )
        out[t] = buf[depth + k - 1]


@dataclass(frozen=True, eq=False)
class NarxModel:
    """A polynomial NARX model (see the module text).

    Parameters
    ----------
    structure : NarxStructure
        Lags, channels and candidates.
    terms : tuple of ndarray of int
        Selected candidate monomials, one array per output.
    theta : tuple of ndarray
        Their parameters, one array per output.
    covariance : tuple of ndarray
        Parameter covariance per output, shapes (n_i, n_i).
    Ts : float
        Sample time in seconds.
    noise_variance : ndarray, shape (ny,)
        One-step residual variance per output on the estimation data.
    output_names, input_names, output_units, input_units : tuple of str
        Channel labels.
    report : EstimationReport or None
        Estimation summary.
    err : tuple of ndarray
        Error reduction ratio of each selected term, one array per output.
    """

    structure: NarxStructure
    terms: tuple[np.ndarray, ...]
    theta: tuple[np.ndarray, ...]
    covariance: tuple[np.ndarray, ...]
    Ts: float
    noise_variance: np.ndarray
    output_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    output_units: tuple[str, ...] = ()
    input_units: tuple[str, ...] = ()
    report: EstimationReport | None = None
    err: tuple[np.ndarray, ...] = ()

    def __post_init__(self) -> None:
        s = self.structure
        if not self.output_names:
            object.__setattr__(self, 'output_names', tuple(f'y{i + 1}' for i in range(s.ny)))
        if not self.input_names:
            object.__setattr__(self, 'input_names', tuple(f'u{i + 1}' for i in range(s.nu)))
        if not self.output_units:
            object.__setattr__(self, 'output_units', ('',) * s.ny)
        if not self.input_units:
            object.__setattr__(self, 'input_units', ('',) * s.nu)

    @property
    def ny(self) -> int:
        """Number of outputs."""
        return self.structure.ny

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return self.structure.nu

    @property
    def n_params(self) -> int:
        """Number of estimated parameters (all outputs)."""
        return int(sum(len(t) for t in self.terms))

    @property
    def std(self) -> tuple[np.ndarray, ...]:
        """Parameter standard deviations, one array per output."""
        return tuple(np.sqrt(np.clip(np.diag(c), 0.0, None)) for c in self.covariance)

    def term_names(self, output: int) -> list[str]:
        """Text of the selected terms of one output, in selection order.

        Parameters
        ----------
        output : int
            Output index, ``0..ny-1``.
        """
        return [
            self.structure.term_name(int(t), self.output_names, self.input_names)
            for t in self.terms[output]
        ]

    def _arrays(self) -> tuple[np.ndarray, ...]:
        kinds, chans, lags, factors, owner = self.structure.term_arrays(self.terms)
        theta = np.concatenate([np.asarray(t, dtype=float) for t in self.theta])
        return kinds, chans, lags, factors, owner, theta

    def _check(self, data: IdData) -> None:
        if not isinstance(data, IdData):
            raise TypeError(f'data must be IdData, got {type(data).__name__}')
        if data.ny != self.ny or data.nu != self.nu:
            raise ValueError(
                f'data has ny={data.ny}, nu={data.nu}; model has ny={self.ny}, nu={self.nu}'
            )

    def simulate(self, data: IdData, ic: str = 'estimate') -> np.ndarray:
        """Simulate the outputs from the inputs (free run, no measured outputs used).

        Parameters
        ----------
        data : IdData
            Inputs; with ``ic='estimate'`` the first ``max_lag`` measured
            outputs are the initial conditions.
        ic : {'estimate', 'zero'}
            Initial conditions: the measured first samples, or zeros.

        Returns
        -------
        ndarray, shape (N, ny)
            Simulated outputs (diverging samples are NaN).
        """
        if ic not in ('zero', 'estimate'):
            raise ValueError(f"ic must be 'zero' or 'estimate', got {ic!r}")
        self._check(data)
        start = self.structure.max_lag
        y = np.zeros((data.N, self.ny))
        if ic == 'estimate':
            y[:start] = data.y[:start]
        stop = _simulate(y, np.ascontiguousarray(data.u), start, *self._arrays())
        y[stop:] = np.nan
        return y

    def predict(self, data: IdData, k: int = 1, ic: str = 'estimate') -> np.ndarray:
        """Predict ``k`` steps ahead, ``yhat(t | t-k)``, shape (N, ny).

        The first ``max_lag + k - 1`` samples (no prediction possible) are the
        measured outputs with ``ic='estimate'``, zeros with ``ic='zero'``.

        Parameters
        ----------
        data : IdData
            Measured outputs and inputs, ``ny`` and ``nu`` as the model.
        k : int
            Prediction horizon in samples (>= 1).
        ic : {'estimate', 'zero'}
            The first samples: the measured outputs, or zeros.
        """
        if int(k) < 1:
            raise ValueError(f'prediction horizon k must be >= 1, got {k!r}')
        if ic not in ('zero', 'estimate'):
            raise ValueError(f"ic must be 'zero' or 'estimate', got {ic!r}")
        self._check(data)
        start = self.structure.max_lag
        out = data.y.copy() if ic == 'estimate' else np.zeros((data.N, self.ny))
        y = np.ascontiguousarray(data.y)
        _predict(y, np.ascontiguousarray(data.u), int(k), start, *self._arrays(), out)
        return out

    def residuals(self, data: IdData, ic: str = 'estimate') -> np.ndarray:
        """One-step prediction errors, shape (N, ny) (zero for the first ``max_lag``).

        ``ic`` is accepted as by :meth:`PolyModel.residuals`; the predictor
        always starts from the measured outputs.

        Parameters
        ----------
        data : IdData
            Measured outputs and inputs, ``ny`` and ``nu`` as the model.
        ic : {'estimate', 'zero'}
            Accepted for compatibility; has no effect.
        """
        return data.y - self.predict(data, 1, ic='estimate')

    def __str__(self) -> str:
        s = self.structure
        lines = [
            f'Discrete-time polynomial NARX model ({self.ny} output(s), {self.nu} input(s)): '
            f'degree {s.degree}, output lags 1..{s.na}, input lags '
            f'{s.nk}..{s.nk + s.nb - 1}; {len(s.monomials)} candidate terms'
        ]
        for i in range(self.ny):
            lines.append(f'  {self.output_names[i]}(t) =')
            std = self.std[i]
            errs = self.err[i] if len(self.err) > i else np.full(len(self.terms[i]), np.nan)
            for name, value, sd, e in zip(
                self.term_names(i), self.theta[i], std, errs, strict=True
            ):
                lines.append(f'    {value:+.6g} * {name}   (std {sd:.3g}, ERR {100 * e:.3g} %)')
        lines.append(f'  Number of selected terms: {self.n_params}')
        lines.append(f'  Sample time: {self.Ts:g} seconds')
        if self.report is not None:
            fits = ', '.join(f'{f:.2f}%' for f in self.report.fit)
            lines.append(
                f'  Estimated with {self.report.method} on {self.report.n_samples} samples.'
            )
            lines.append(f'  Fit to estimation data: {fits} (prediction focus)')
        return '\n'.join(lines)


def narx(
    data: IdData | Sequence[IdData],
    na: int,
    nb: int,
    nk: int = 1,
    degree: int = 2,
    criterion: str = 'bic',
    max_terms: int = 30,
    n_terms: int | None = None,
) -> NarxModel:
    """Estimate a polynomial NARX model with FROLS structure selection, one per output.

    Parameters
    ----------
    data : IdData or sequence of IdData
        Estimation data; several experiments are stacked without crossing
        their boundaries.
    na : int
        Output lags ``1..na`` of every output.
    nb : int
        Input lags per input (``nk..nk+nb-1``).
    nk : int
        Input delay in samples.
    degree : int
        Largest monomial degree.
    criterion : {'bic', 'aic', 'fpe'}
        Information criterion for the number of terms.
    max_terms : int
        Most terms per output.
    n_terms : int, optional
        Exactly this many terms per output (no criterion).

    Returns
    -------
    NarxModel
        The model, with parameter covariances and the selected terms.
    """
    experiments = as_experiments(data)
    first = experiments[0]
    structure = NarxStructure(first.ny, first.nu, int(na), int(nb), int(nk), int(degree))
    start = structure.max_lag
    if any(d.N <= start + 1 for d in experiments):
        raise ValueError(f'every experiment needs more than {start + 1} samples for these lags')
    P = np.vstack([structure.candidates(d.y, d.u) for d in experiments])
    Y = np.vstack([d.y[start:] for d in experiments])
    terms, thetas, covs, errs, noise = [], [], [], [], []
    for i in range(structure.ny):
        result = frols(P, Y[:, i], max_terms=max_terms, criterion=criterion, n_terms=n_terms)
        terms.append(result.selected)
        thetas.append(result.theta)
        covs.append(result.covariance)
        errs.append(result.err[: len(result.selected)])
        noise.append(result.noise_variance)
    model = NarxModel(
        structure,
        tuple(terms),
        tuple(thetas),
        tuple(covs),
        first.Ts,
        np.asarray(noise),
        first.output_names,
        first.input_names,
        first.output_units,
        first.input_units,
        err=tuple(errs),
    )
    e = np.vstack([model.residuals(d)[start:] for d in experiments])
    yhat = Y - e
    report = EstimationReport(
        method=f'FROLS ({criterion.upper()}), least squares',
        n_samples=int(Y.shape[0]),
        fit=fit_percent(Y, yhat),
        mse=np.mean(e**2, axis=0),
        fpe=float('nan'),
        aic=float('nan'),
    )
    object.__setattr__(model, 'report', report)
    return model
