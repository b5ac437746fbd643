"""Several experiments as one data set: estimation by experiment and k-fold cross-validation.

Every estimator (:func:`~maglev_ros.sysid.arx`, :func:`~maglev_ros.sysid.iv4`,
:func:`~maglev_ros.sysid.armax`, :func:`~maglev_ros.sysid.narx.narx`) takes a
sequence of :class:`~maglev_ros.sysid.IdData` and builds its regressors per
experiment, so no sample of one experiment is joined to another's.  This
module validates across experiments:

- :func:`kfold` splits the experiments into ``k`` folds (``k`` = number of
  experiments: leave one experiment out), estimates on all folds but one and
  validates on the held-out one, for each fold in turn;
- :func:`by_experiment` estimates on each experiment alone and validates on
  all the others.

Both return a :class:`FoldTable` that prints one row per fold.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .criteria import fit_percent
from .dataset import IdData, as_experiments

__all__ = ['Fold', 'FoldTable', 'by_experiment', 'kfold']


@dataclass(frozen=True)
class Fold:
    """One fold: which experiments estimated, which validated, and the fits.

    Attributes
    ----------
    estimation, validation : tuple of int
        Experiment indices (0-based).
    fit : ndarray, shape (ny,)
        Validation fit in percent per output (all validation experiments).
    model : object
        The model estimated on this fold (``None`` if it failed).
    error : str
        Why the estimation or validation failed (empty if it did not).
    """

    estimation: tuple[int, ...]
    validation: tuple[int, ...]
    fit: np.ndarray
    model: object = None
    error: str = ''


@dataclass(frozen=True)
class FoldTable:
    """Folds of a cross-validation over experiments.

    Attributes
    ----------
    folds : tuple of Fold
    labels : tuple of str
        Experiment names (file names).
    output_names : tuple of str
    horizon : int or None
        Prediction horizon of the fits, None for simulation.
    """

    folds: tuple[Fold, ...]
    labels: tuple[str, ...]
    output_names: tuple[str, ...]
    horizon: int | None = None

    @property
    def fits(self) -> np.ndarray:
        """Validation fits, shape (n_folds, ny) (NaN for failed folds)."""
        return np.array([f.fit for f in self.folds])

    @property
    def mean(self) -> np.ndarray:
        """Mean fit over the folds that worked, shape (ny,)."""
        return np.nanmean(self.fits, axis=0)

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of the fit over the folds that worked, shape (ny,)."""
        return np.nanstd(self.fits, axis=0)

    def to_dict(self) -> dict:
        """Plain-type summary for JSON."""
        return {
            'horizon': self.horizon,
            'experiments': list(self.labels),
            'folds': [
                {
                    'estimation': [self.labels[i] for i in f.estimation],
                    'validation': [self.labels[i] for i in f.validation],
                    'fit': [float(v) for v in f.fit],
                    'error': f.error,
                }
                for f in self.folds
            ],
            'mean_fit': [float(v) for v in self.mean],
            'std_fit': [float(v) for v in self.std],
        }

    def text(self) -> str:
        """Return the fold table: one row per fold and a mean row."""
        what = 'simulation' if self.horizon is None else f'{self.horizon}-step prediction'
        names = ', '.join(self.output_names)
        head = f'{"fold":>4}  {"estimated on":<28} {"validated on":<22} fit % ({names}, {what})'
        lines = [head, '-' * len(head)]
        for k, f in enumerate(self.folds, start=1):
            est = ', '.join(self.labels[i] for i in f.estimation)
            val = ', '.join(self.labels[i] for i in f.validation)
            fit = f.error or ', '.join(f'{v:.2f}' for v in f.fit)
            lines.append(f'{k:>4}  {est[:28]:<28} {val[:22]:<22} {fit}')
        mean = ', '.join(f'{m:.2f} +- {s:.2f}' for m, s in zip(self.mean, self.std, strict=True))
        lines.append(f'{"mean":>4}  {"":<28} {"":<22} {mean}')
        return '\n'.join(lines)


def _fit(model: object, data: Sequence[IdData], horizon: int | None, ic: str) -> np.ndarray:
    y = np.vstack([d.y for d in data])
    if horizon is None:
        yhat = np.vstack([model.simulate(d, ic=ic) for d in data])
    else:
        yhat = np.vstack([model.predict(d, horizon, ic=ic) for d in data])
    return fit_percent(y, yhat)


def _run(
    splits: Sequence[tuple[tuple[int, ...], tuple[int, ...]]],
    experiments: tuple[IdData, ...],
    estimator: Callable[[Sequence[IdData]], object],
    labels: Sequence[str] | None,
    horizon: int | None,
    ic: str,
) -> FoldTable:
    folds = []
    ny = experiments[0].ny
    for est, val in splits:
        try:
            model = estimator([experiments[i] for i in est])
            fit = _fit(model, [experiments[i] for i in val], horizon, ic)
            folds.append(Fold(est, val, fit, model))
        except (ValueError, np.linalg.LinAlgError) as exc:  # a fold's failure is a row
            folds.append(Fold(est, val, np.full(ny, np.nan), None, f'failed: {exc}'))
    names = tuple(labels) if labels else tuple(f'exp{i + 1}' for i in range(len(experiments)))
    return FoldTable(tuple(folds), names, experiments[0].output_names, horizon)


def kfold(
    data: Sequence[IdData],
    estimator: Callable[[Sequence[IdData]], object],
    k: int | None = None,
    labels: Sequence[str] | None = None,
    horizon: int | None = None,
    ic: str = 'estimate',
) -> FoldTable:
    """K-fold cross-validation over experiments (default: leave one experiment out).

    Parameters
    ----------
    data : sequence of IdData
        At least two experiments.
    estimator : callable
        ``estimator(experiments) -> model`` (e.g. ``lambda d: arx(d, 7, 9, 1)``).
    k : int, optional
        Number of folds, 2..number of experiments; experiment ``i`` goes to
        fold ``i mod k``.
    labels : sequence of str, optional
        Experiment names for the table.
    horizon : int or None
        Validation by k-step prediction instead of simulation.
    ic : {'estimate', 'zero'}
        Initial conditions of the validation.

    Returns
    -------
    FoldTable
        One row per fold.
    """
    experiments = as_experiments(data)
    n = len(experiments)
    k = n if k is None else int(k)
    if n < 2 or not 2 <= k <= n:
        raise ValueError(
            f'k-fold over experiments needs 2 <= k <= {n} experiments, got k={k}: '
            'give at least two data files'
        )
    groups = [tuple(i for i in range(n) if i % k == fold) for fold in range(k)]
    splits = [(tuple(i for i in range(n) if i not in g), g) for g in groups]
    return _run(splits, experiments, estimator, labels, horizon, ic)


def by_experiment(
    data: Sequence[IdData],
    estimator: Callable[[Sequence[IdData]], object],
    labels: Sequence[str] | None = None,
    horizon: int | None = None,
    ic: str = 'estimate',
) -> FoldTable:
    """Estimate on each experiment alone, validate on all the others.

    Parameters
    ----------
    data : sequence of IdData
        At least two experiments.
    estimator : callable
        ``estimator(experiments) -> model`` (e.g. ``lambda d: arx(d, 7, 9, 1)``).
    labels : sequence of str, optional
        Experiment names for the table.
    horizon : int or None
        Validation by k-step prediction instead of simulation.
    ic : {'estimate', 'zero'}
        Initial conditions of the validation.

    Returns
    -------
    FoldTable
        One row per experiment (estimated on it, validated on the others).
    """
    experiments = as_experiments(data)
    n = len(experiments)
    if n < 2:
        raise ValueError('validation by experiment needs at least two experiments')
    splits = [((i,), tuple(j for j in range(n) if j != i)) for i in range(n)]
    return _run(splits, experiments, estimator, labels, horizon, ic)
