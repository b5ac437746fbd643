"""Model validation: ``compare`` (fit percentage) and residual analysis (``resid``).

Fit is the toolbox's ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` per output.
Residual analysis follows Ljung (sec. 16.6): the normalized autocorrelation
``r_e(tau)``, ``tau = 1..M``, and input-residual cross-correlation
``r_eu(tau) = corr(e(t + tau), u(t))``, ``tau = 0..M``, of white residuals
independent of the input are ~ N(0, 1/N), so the 99 % bound per lag is
``2.576 / sqrt(N)``.  The verdict uses the portmanteau statistics
``N sum r^2`` against the 99 % quantile of chi-square with M (resp. M + 1)
degrees of freedom, which keeps the false-alarm rate at 1 % overall rather
than per lag; with several outputs (inputs) the level is divided among the
``ny`` whiteness and ``ny nu`` independence tests (Bonferroni), so a correct
MIMO model also fails with at most 1 % probability per test family.

The input-residual correlation is also computed at *negative* lags,
``r_eu(-tau) = corr(e(t), u(t + tau))``: an input that reacts to past residuals
is fed back (closed loop, :mod:`~.feedback`).  There, the input at lag 0 may
react to the same sample's noise (a controller without delay), so with
``closed_loop=True`` the independence test uses lags ``1..M`` only; the negative
lags are shown, not tested (feedback is not a model error).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from .criteria import fit_percent
from .dataset import IdData
from .feedback import lagged_correlation
from .model import PolyModel

__all__ = ['CompareResult', 'ResidualAnalysis', 'compare', 'resid']


@dataclass(frozen=True)
class CompareResult:
    """Outcome of :func:`compare`.

    Attributes
    ----------
    yhat : ndarray, shape (N, ny)
        Simulated or predicted outputs.
    fit : ndarray, shape (ny,)
        Fit in percent per output.
    horizon : int or None
        Prediction horizon in samples, None for simulation.
    """

    yhat: np.ndarray
    fit: np.ndarray
    horizon: int | None


def compare(
    model: PolyModel, data: IdData, horizon: int | None = None, ic: str = 'zero'
) -> CompareResult:
    """Compare model output with measured output, as the toolbox's ``compare``.

    Parameters
    ----------
    model : PolyModel
        Identified model.
    data : IdData
        Validation (or estimation) data.
    horizon : int or None
        ``None`` (or ``inf``): pure simulation from the inputs; ``k``: k-step-ahead
        prediction.
    ic : {'zero', 'estimate'}
        Initial conditions: zero, or least-squares estimated from the data.

    Returns
    -------
    CompareResult
        Model outputs and fit.
    """
    if horizon is None or horizon == np.inf:
        yhat = model.simulate(data, ic=ic)
        k = None
    else:
        k = int(horizon)
        yhat = model.predict(data, k=k, ic=ic)
    return CompareResult(yhat=yhat, fit=fit_percent(data.y, yhat), horizon=k)


@dataclass(frozen=True)
class ResidualAnalysis:
    """Outcome of :func:`resid`.

    Attributes
    ----------
    residuals : ndarray, shape (N, ny)
        One-step prediction errors.
    lags : ndarray, shape (M + 1,)
        Lags 0..M in samples.
    autocorr : ndarray, shape (ny, M + 1)
        Normalized residual autocorrelation (``autocorr[:, 0] = 1``).
    crosscorr : ndarray, shape (ny, nu, M + 1)
        Normalized correlation of ``e_i(t + tau)`` with ``u_j(t)``.
    bound : float
        99 % confidence bound per lag, ``2.576 / sqrt(N)``.
    whiteness_stat, independence_stat : ndarray
        Portmanteau statistics, shapes (ny,) and (ny, nu).
    whiteness_limit, independence_limit : float
        Their 99 % chi-square limits.
    feedback_corr : ndarray, shape (ny, nu, M)
        ``corr(e_i(t), u_j(t + tau))`` for ``tau = 1..M``: the cross-correlation
        at lags ``-1..-M`` (non-zero when the input is fed back).
    closed_loop : bool
        True if the independence test skipped lag 0 (closed-loop data).
    noise_model : bool
        False for structures without a noise model (OE, IV): their residuals
        are the output disturbance, coloured in general, so whiteness is shown
        but not required.
    against : str
        ``'inputs'``, or ``'instruments'`` when the independence test used the
        external instruments (closed-loop IV: the inputs depend on the noise,
        the instruments do not).
    """

    residuals: np.ndarray
    lags: np.ndarray
    autocorr: np.ndarray
    crosscorr: np.ndarray
    bound: float
    whiteness_stat: np.ndarray
    independence_stat: np.ndarray
    whiteness_limit: float
    independence_limit: float
    feedback_corr: np.ndarray | None = None
    closed_loop: bool = False
    noise_model: bool = True
    against: str = 'inputs'

    @property
    def white(self) -> bool:
        """True if all residual autocorrelation tests pass at 99 %."""
        return bool(np.all(self.whiteness_stat < self.whiteness_limit))

    @property
    def independent(self) -> bool:
        """True if all input-residual independence tests pass at 99 %."""
        return bool(np.all(self.independence_stat < self.independence_limit))

    @property
    def failed_tests(self) -> tuple[str, ...]:
        """Names of the failed tests: ``'whiteness'``, ``'independence'`` (empty if passed)."""
        white = self.white or not self.noise_model
        return tuple(
            name for name, ok in (('whiteness', white), ('independence', self.independent))
            if not ok
        )  # fmt: skip

    @property
    def passed(self) -> bool:
        """Overall verdict: white (if the model has a noise model) and independent."""
        return not self.failed_tests

    def summary(self) -> str:
        """Return a one-line verdict."""
        verdict = 'PASS' if self.passed else 'FAIL'
        white = 'ok' if self.white else 'failed' if self.noise_model else 'not required'
        indep = 'ok' if self.independent else 'failed'
        what = 'instrument' if self.against == 'instruments' else 'input'
        lags = ' (lags >= 1)' if self.closed_loop else ''
        return (
            f'residual analysis {verdict} (99 %): whiteness {white} '
            f'(statistic {self.whiteness_stat.max():.1f}, limit {self.whiteness_limit:.1f}), '
            f'{what} independence{lags} {indep} (statistic '
            f'{self.independence_stat.max(initial=0):.1f}, limit '
            f'{self.independence_limit:.1f})'
        )


_xcorr = lagged_correlation


def resid(
    model: PolyModel,
    data: IdData | Sequence[IdData],
    max_lag: int = 25,
    skip: int | None = None,
    closed_loop: bool = False,
    instruments: np.ndarray | None = None,
    noise_model: bool = True,
) -> ResidualAnalysis:
    """Residual analysis: whiteness and input independence of the prediction errors.

    Parameters
    ----------
    model : PolyModel
        Identified model.
    data : IdData
        Data to analyse (validation data is the stronger test).
    max_lag : int
        Largest lag ``M`` in samples.
    skip : int, optional
        Initial samples to drop (predictor transient); default the model's
        largest order.
    closed_loop : bool
        Closed-loop data: the independence test uses lags ``1..M`` (lag 0 may
        carry the controller's reaction to the same sample).
    instruments : ndarray, shape (N, nz), optional
        External instruments of ``data``'s samples: the independence test is
        made against them instead of the inputs.
    noise_model : bool
        False for structures without a noise model (whiteness not required).

    Returns
    -------
    ResidualAnalysis
        Correlations, bounds and verdict.
    """
    if isinstance(data, (list, tuple)):
        data = data[0]
    if max_lag < 1:
        raise ValueError(f'max_lag must be >= 1, got {max_lag!r}')
    e = model.residuals(data)
    start = (
        int(
            max(
                model.A.shape[2],
                model.B.shape[2],
                model.C.shape[1],
                model.D.shape[1],
                model.F.shape[2],
            )
        )
        if skip is None
        else int(skip)
    )
    e_used, u_used = e[start:], data.u[start:]
    if not np.all(np.isfinite(e_used)):
        raise FloatingPointError('the residuals are not finite (the predictor diverges)')
    N = e_used.shape[0]
    if N <= 2 * max_lag:
        raise ValueError(f'max_lag={max_lag} is too large for {N} residual samples')
    auto = np.array([_xcorr(e_used[:, i], e_used[:, i], max_lag) for i in range(model.ny)])
    cross = np.array(
        [
            [_xcorr(e_used[:, i], u_used[:, j], max_lag) for j in range(model.nu)]
            for i in range(model.ny)
        ]
    ).reshape(model.ny, model.nu, max_lag + 1)
    back = np.array(
        [
            [_xcorr(u_used[:, j], e_used[:, i], max_lag)[1:] for j in range(model.nu)]
            for i in range(model.ny)
        ]
    ).reshape(model.ny, model.nu, max_lag)
    first = 1 if closed_loop else 0
    white_stat = N * np.sum(auto[:, 1:] ** 2, axis=1)
    tested = cross
    if instruments is not None:
        z = np.asarray(instruments, dtype=float).reshape(data.N, -1)[start:]
        tested = np.array(
            [
                [_xcorr(e_used[:, i], z[:, j], max_lag) for j in range(z.shape[1])]
                for i in range(model.ny)
            ]
        ).reshape(model.ny, z.shape[1], max_lag + 1)
        first = 0  # the instruments do not react to the noise
    indep_stat = N * np.sum(tested[:, :, first:] ** 2, axis=2)
    return ResidualAnalysis(
        residuals=e,
        lags=np.arange(max_lag + 1),
        autocorr=auto,
        crosscorr=cross,
        bound=float(stats.norm.ppf(0.995) / np.sqrt(N)),
        whiteness_stat=white_stat,
        independence_stat=indep_stat,
        whiteness_limit=float(stats.chi2.ppf(1 - 0.01 / model.ny, max_lag)),
        independence_limit=float(
            stats.chi2.ppf(1 - 0.01 / (model.ny * tested.shape[1]), max_lag + 1 - first)
        ),
        feedback_corr=back,
        closed_loop=closed_loop and instruments is None,
        noise_model=noise_model,
        against='inputs' if instruments is None else 'instruments',
    )
