"""The bounded least-squares fit both grey-box calibrations run.

The static and the dynamic calibration differ in their residual (field
readings vs. Kalman-predictor innovations); the rest of the fit is one
procedure: keep only the identified parameters, fit the scaled deviation
``z = (value - nominal) / scale`` inside the parameter bounds with scipy's
trust-region reflective ``least_squares``, and turn the Jacobian at the
optimum into standard deviations and correlations.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from .errors import GreyBoxError
from .identifiability import Identifiability, analyse
from .parameters import ParameterVector

__all__ = [
    'FitProblem',
    'IdentifiedProblem',
    'ParameterSpread',
    'fit_bounded',
    'identified',
    'spread',
]


class FitProblem(Protocol):
    """What the fit needs of a calibration problem (static or dynamic)."""

    free: Any

    def residual(self, z: np.ndarray) -> np.ndarray:
        """Weighted residuals at the scaled deviation.

        Parameters
        ----------
        z : numpy.ndarray
            Scaled deviation from the nominal values, shape (free parameters,).
        """

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """Jacobian of the residual, shape (residuals, free parameters).

        Parameters
        ----------
        z : numpy.ndarray
            Scaled deviation from the nominal values, shape (free parameters,).
        """


@dataclass(frozen=True)
class IdentifiedProblem:
    """A problem restricted to the parameters the data identify.

    Attributes
    ----------
    problem : FitProblem
        The problem over the kept parameters (the given one if all are kept).
    vector : ParameterVector
        The parameter vector with only the kept parameters free.
    keep : list of str
        Names of the kept (identified) free parameters.
    identifiability : Identifiability
        The analysis at the nominal values.
    """

    problem: Any
    vector: ParameterVector
    keep: list[str]
    identifiability: Identifiability


@dataclass(frozen=True)
class ParameterSpread:
    """Standard deviations and correlations of the fitted parameters.

    Attributes
    ----------
    names : tuple of str
        The fitted parameters' names.
    std : dict
        Standard deviation per name, in the parameter's unit.
    correlation : numpy.ndarray
        Correlation matrix, shape (len(names), len(names)).
    """

    names: tuple[str, ...]
    std: dict[str, float]
    correlation: np.ndarray


def identified(
    problem: FitProblem,
    vector: ParameterVector,
    rebuild: Callable[[ParameterVector], Any],
    say: Callable[[str], None],
) -> IdentifiedProblem:
    """Analyse identifiability at the nominal values and drop what is not identified.

    Parameters
    ----------
    problem : FitProblem
        The problem over all free parameters of ``vector``.
    vector : ParameterVector
        The parameter vector the problem was built from.
    rebuild : callable
        ``rebuild(vector)`` builds the same problem over another vector.
    say : callable
        Progress sink, one line per call.

    Returns
    -------
    IdentifiedProblem
        The problem over the identified parameters.

    Raises
    ------
    GreyBoxError
        None of the free parameters is identified.
    """
    ident = analyse(problem.jacobian(np.zeros(len(problem.free))), problem.free)
    for line in ident.lines():
        say(line)
    keep = [s.name for s in problem.free if s.name not in ident.unidentified_names]
    if not keep:
        raise GreyBoxError(
            'none of the free parameters is identified by these data: ' + '; '.join(ident.lines())
        )
    vector_fit = vector.with_free(keep) if len(keep) < len(problem.free) else vector
    if vector_fit is not vector:
        problem = rebuild(vector_fit)
    return IdentifiedProblem(problem, vector_fit, keep, ident)


def fit_bounded(
    problem: FitProblem,
    analytic_jacobian: bool,
    tolerance: float,
    max_nfev: int,
    report: Callable[[int, np.ndarray], None],
) -> OptimizeResult:
    """Fit the scaled deviation inside the parameter bounds, from the nominal values.

    Parameters
    ----------
    problem : FitProblem
        The problem to fit.
    analytic_jacobian : bool
        Use ``problem.jacobian`` (True) or scipy's 2-point differences.
    tolerance : float
        ``ftol``, ``xtol`` and ``gtol`` of ``least_squares``.
    max_nfev : int
        Most residual evaluations.
    report : callable
        ``report(iteration, residual)``, called at each Jacobian evaluation.

    Returns
    -------
    scipy.optimize.OptimizeResult
        The ``least_squares`` result; ``x`` is the scaled deviation.
    """
    lower = np.array([(s.lower - s.nominal) / s.scale for s in problem.free])
    upper = np.array([(s.upper - s.nominal) / s.scale for s in problem.free])
    iteration = [0]

    def jac(z):
        iteration[0] += 1
        report(iteration[0], problem.residual(z))
        return problem.jacobian(z)

    return least_squares(
        problem.residual,
        np.zeros(len(problem.free)),
        jac=jac if analytic_jacobian else '2-point',
        bounds=(lower, upper),
        method='trf',
        x_scale=1.0,
        ftol=tolerance,
        xtol=tolerance,
        gtol=tolerance,
        max_nfev=max_nfev,
    )


def spread(problem: FitProblem, jacobian: np.ndarray, s2: float) -> ParameterSpread:
    """Compute standard deviations and correlations from the Jacobian at the optimum.

    Parameters
    ----------
    problem : FitProblem
        The fitted problem (its ``free`` specs give names and scales).
    jacobian : numpy.ndarray
        Residual Jacobian at the optimum, shape (residuals, free parameters).
    s2 : float
        Residual variance per degree of freedom.

    Returns
    -------
    ParameterSpread
        Standard deviations in parameter units and the correlation matrix.
    """
    cov_z = np.linalg.pinv(jacobian.T @ jacobian) * s2
    sd_z = np.sqrt(np.clip(np.diag(cov_z), 0, None))
    with np.errstate(divide='ignore', invalid='ignore'):
        corr = cov_z / np.outer(sd_z, sd_z)
    names = tuple(s.name for s in problem.free)
    std = {n: float(sd * s.scale) for n, sd, s in zip(names, sd_z, problem.free, strict=True)}
    return ParameterSpread(names, std, corr)
