"""Feedback detection: tell whether a data set was taken in closed loop.

In open loop the input does not depend on the output's disturbances, so the
innovations ``e(t)`` of any good model are uncorrelated with the new part of the
inputs at the same and *later* times ``u(t + tau)``, ``tau >= 0`` (for a plant
without direct feedthrough, ``nk >= 1``).  A controller that reacts to the
measured output makes later inputs depend on past disturbances (Ljung,
sec. 13.4 and 16.6): the cross-correlation ``r_eu(-tau) = corr(e(t), u(t + tau))``
at *negative* lags (and at lag 0 for a controller that reacts within the
sample) is significant.  :func:`detect_feedback` computes it with the
innovations of a high-order ARX model (a nearly model-free whitening of the
outputs) and the inputs prewhitened by their own past (a coloured input would
otherwise carry any bias of the whitening model into the test), and tests
``N sum_tau r^2`` over ``tau = 0..M`` per input/output pair against the
chi-square quantile with ``M + 1`` degrees of freedom at 99.9 % (a flag that
rarely fires on open-loop data).

A closed loop can still identify the plant if something other than the
controller moves the input (an excitation, a reference change).
:func:`detect_feedback` therefore also fits the controller: each input
regressed on the present and past outputs and its own past (ARX, same order).
The unexplained share of the input's standard deviation is the *external
excitation share*; below :data:`EXCITATION_SHARE` (5 %) the input is, to that
precision, a linear function of the outputs, and no method can separate the
plant from the controller without an external signal (the data are not
informative: the stable model of the loop and the unstable plant predict
equally well).

Why it matters: a model fitted to closed-loop data by a method that ignores
the feedback (output error, IV with the input as instrument) describes the
loop, not the plant; a stable fit of an open-loop-unstable plant is the
typical result.  What to do instead: instrumental variables with an external
excitation as instrument (``--instruments``), or a prediction-error method
with a noise model (ARMAX, BJ) judged on k-step prediction.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .arx import arx
from .dataset import IdData

__all__ = ['ADVICE', 'FeedbackTest', 'detect_feedback', 'lagged_correlation']

#: What to do with closed-loop data (shown by the command line and in its JSON).
ADVICE = (
    'the data were taken in closed loop (the input reacts to past output '
    'disturbances): a model fitted as if in open loop describes the loop, not the '
    'plant. Record an excitation or reference signal and use it as instrument '
    '(--iv with --instruments CHANNEL), or use a prediction-error method with a '
    'noise model (--armax, --bj) and judge it on k-step prediction (--horizon), '
    'not on simulation'
)
LEVEL = 0.999  # confidence of the feedback flag
#: Below this unexplained share of an input's standard deviation, the input is
#: taken as the controller's output alone (no external excitation).
EXCITATION_SHARE = 0.05
MAX_ORDER = 20  # orders of the whitening ARX model


def lagged_correlation(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """Return the normalized ``corr(a(t + tau), b(t))`` for ``tau = 0..max_lag``.

    Parameters
    ----------
    a, b : ndarray, shape (N,)
        Signals (means are removed).
    max_lag : int
        Largest lag in samples.

    Returns
    -------
    ndarray, shape (max_lag + 1,)
        ``sum_t a(t + tau) b(t) / (N std a std b)``; zeros if a signal is constant.
    """
    a = a - a.mean()
    b = b - b.mean()
    n = len(a)
    scale = n * a.std() * b.std()
    if scale == 0:
        return np.zeros(max_lag + 1)
    return np.array([a[tau:] @ b[: n - tau] for tau in range(max_lag + 1)]) / scale


@dataclass(frozen=True)
class FeedbackTest:
    """Outcome of :func:`detect_feedback`.

    Attributes
    ----------
    correlation : ndarray, shape (ny, nu, M + 1)
        ``corr(u_j(t + tau), e_i(t))`` for ``tau = 0..M`` (lag ``-tau`` of
        ``r_eu``), ``u`` prewhitened.
    statistic : ndarray, shape (ny, nu)
        ``N sum_tau correlation^2`` per pair.
    limit : float
        Chi-square quantile (``M + 1`` degrees of freedom, 99.9 %).
    bound : float
        Per-lag 99 % bound ``2.576 / sqrt(N)`` (for plots).
    pairs : tuple of (str, str)
        ``(output, input)`` names of the pairs whose statistic exceeds the limit.
    excitation_share : ndarray, shape (nu,)
        Per input, the standard deviation of what a linear controller of the
        outputs does not explain, relative to the input's (0: the controller
        alone moves it; 1: nothing of it is explained).
    input_names : tuple of str
        The inputs' names.
    """

    correlation: np.ndarray
    statistic: np.ndarray
    limit: float
    bound: float
    pairs: tuple[tuple[str, str], ...]
    excitation_share: np.ndarray = field(default_factory=lambda: np.ones(0))
    input_names: tuple[str, ...] = ()

    @property
    def unexcited(self) -> tuple[str, ...]:
        """Fed-back inputs that have no external excitation (share below 5 %)."""
        fed = {u for _, u in self.pairs}
        return tuple(
            name
            for name, share in zip(self.input_names, self.excitation_share, strict=True)
            if name in fed and share < EXCITATION_SHARE
        )

    @property
    def informative(self) -> bool:
        """False in closed loop when some fed-back input has no external excitation."""
        return not self.unexcited

    @property
    def closed_loop(self) -> bool:
        """True if some input reacts to past output innovations."""
        return bool(self.pairs)

    def summary(self) -> str:
        """One line: the verdict and the largest statistic against its limit."""
        top = float(self.statistic.max(initial=0.0))
        if not self.closed_loop:
            return (
                f'no feedback detected (input vs past output innovations: statistic '
                f'{top:.1f}, limit {self.limit:.1f})'
            )
        shown = ', '.join(f'{u} reacts to {y}' for y, u in self.pairs[:4])
        text = (
            f'closed loop: {shown} (input vs past output innovations: statistic '
            f'{top:.1f}, limit {self.limit:.1f})'
        )
        shares = ', '.join(
            f'{name} {100 * share:.1f} %'
            for name, share in zip(self.input_names, self.excitation_share, strict=True)
        )
        if self.unexcited:
            return (
                f'{text}; no external excitation (share of the input not explained by a '
                f'linear controller of the outputs: {shares}, below '
                f'{100 * EXCITATION_SHARE:.0f} %): these data cannot separate the plant '
                'from the controller'
            )
        return f'{text}; external excitation share {shares}'

    def as_dict(self) -> dict:
        """JSON-ready summary (statistics per pair, the pairs, the advice)."""
        return {
            'closed_loop': self.closed_loop,
            'statistic': self.statistic.tolist(),
            'limit': self.limit,
            'pairs': [list(p) for p in self.pairs],
            'excitation_share': dict(
                zip(self.input_names, self.excitation_share.tolist(), strict=True)
            ),
            'informative': self.informative,
            'summary': self.summary(),
            'advice': ADVICE if self.closed_loop else '',
        }


def detect_feedback(data: IdData, max_lag: int = 25, order: int | None = None) -> FeedbackTest:
    """Test whether the inputs react to past output innovations (closed loop).

    Parameters
    ----------
    data : IdData
        The data set (detrended as it will be identified).
    max_lag : int
        Number ``M`` of negative lags tested besides lag 0 (samples).
    order : int, optional
        Orders ``na = nb`` of the whitening ARX model (default
        ``min(20, N / (20 (ny + nu)))``, at least 1).

    Returns
    -------
    FeedbackTest
        Correlations, statistics and the verdict.

    Raises
    ------
    ValueError
        If the data have no inputs or too few samples for ``max_lag``.
    """
    if data.nu == 0:
        raise ValueError('feedback detection needs at least one input')
    n = (
        order
        if order is not None
        else max(1, min(MAX_ORDER, data.N // (20 * (data.ny + data.nu))))
    )
    if data.N <= 4 * max_lag + 2 * n:
        raise ValueError(f'{data.N} samples are too few to test {max_lag} lags for feedback')
    with np.errstate(all='ignore'):
        model = arx(data, n, n, 1)
        e = model.residuals(data)[n:]
    u = _prewhitened_inputs(data.u, max(n, 2 * MAX_ORDER))[n:]
    N = e.shape[0]
    corr = np.array(
        [
            [lagged_correlation(u[:, j], e[:, i], max_lag) for j in range(data.nu)]
            for i in range(data.ny)
        ]
    ).reshape(data.ny, data.nu, max_lag + 1)
    stat = N * np.sum(corr**2, axis=2)
    limit = float(stats.chi2.ppf(LEVEL, max_lag + 1))
    pairs = tuple(
        (data.output_names[i], data.input_names[j])
        for i in range(data.ny)
        for j in range(data.nu)
        if stat[i, j] > limit
    )
    return FeedbackTest(
        correlation=corr,
        statistic=stat,
        limit=limit,
        bound=float(stats.norm.ppf(0.995) / np.sqrt(N)),
        pairs=pairs,
        excitation_share=_excitation_share(data, n),
        input_names=tuple(data.input_names),
    )


def _prewhitened_inputs(u: np.ndarray, order: int) -> np.ndarray:
    """Return the inputs minus their least-squares prediction from the inputs' own past (N, nu).

    A coloured input (a held PRBS) correlates with itself; any bias of the
    whitening model then leaks into ``corr(u(t + tau), e(t))`` in open loop too.
    Only what is new in the input at ``t + tau`` can be tested against ``e(t)``.
    """
    centred = u - u.mean(axis=0)
    phi = np.hstack([np.roll(centred, k, axis=0) for k in range(1, order + 1)])[order:]
    out = np.zeros_like(centred)
    theta, *_ = np.linalg.lstsq(phi, centred[order:], rcond=None)
    out[order:] = centred[order:] - phi @ theta
    return out


def _excitation_share(data: IdData, n: int) -> np.ndarray:
    """Per input: std of the residual of ``u(t)`` on ``y(t..t-n)``, ``u(t-1..t-n)``, over std u."""
    shares = []
    for j in range(data.nu):
        u = data.u[:, j] - data.u[:, j].mean()
        columns = [np.roll(data.y - data.y.mean(axis=0), k, axis=0) for k in range(n + 1)]
        others = np.delete(data.u - data.u.mean(axis=0), j, axis=1)
        columns += [np.roll(others, k, axis=0) for k in range(n + 1)]
        columns += [np.roll(u, k)[:, None] for k in range(1, n + 1)]
        phi = np.hstack(columns)[n:]
        target = u[n:]
        scale = float(np.std(target))
        if scale == 0:
            shares.append(0.0)
            continue
        theta, *_ = np.linalg.lstsq(phi, target, rcond=None)
        shares.append(float(np.std(target - phi @ theta)) / scale)
    return np.array(shares)
