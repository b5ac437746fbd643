"""Prediction-error minimization: Levenberg-Marquardt with analytic gradients.

The structures supply ``errors(theta) -> e`` (prediction errors, stacked over
experiments) and ``normal(theta, e) -> (psi^T psi, psi^T e)`` with
``psi = -de/dtheta`` (the regressors filtered with ``scipy.signal.lfilter``;
ARMAX forms the products from lagged correlations without building ``psi``,
see :func:`from_jacobian` for structures that build it).  The step solves
``(psi^T psi + mu diag(psi^T psi)) d = psi^T e`` (Gauss-Newton for ``mu -> 0``);
``mu`` shrinks after an accepted step and grows after a rejected one.  A
projection (root reflection) keeps ``C``, ``D`` and ``F`` stable, i.e. the
predictor filters stable and the noise model minimum phase.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ['PemResult', 'from_jacobian', 'levenberg_marquardt', 'shift', 'stabilize']


@dataclass(frozen=True)
class PemResult:
    """Outcome of :func:`levenberg_marquardt`.

    Attributes
    ----------
    theta : ndarray, shape (p,)
        Minimizer.
    covariance : ndarray, shape (p, p)
        ``lambda (psi^T psi)^-1`` with ``lambda = e^T e / (N - p)``.
    loss : float
        ``e^T e / N`` at the minimizer.
    iterations : int
        Accepted plus rejected steps.
    converged : bool
        False if the iterations stopped at ``max_iter`` (the loss was still
        decreasing by more than ``tol``).
    """

    theta: np.ndarray
    covariance: np.ndarray
    loss: float
    iterations: int
    converged: bool = True


def stabilize(poly: np.ndarray, radius: float = 0.999) -> np.ndarray:
    """Reflect the roots of a monic polynomial in ``q^-1`` into the unit disc.

    Parameters
    ----------
    poly : ndarray, shape (n + 1,)
        Coefficients ``[1, c1, ..., cn]``.
    radius : float
        Roots with modulus above 1 are reflected (``r -> 1/conj(r)``), then
        any modulus above ``radius`` is scaled down to ``radius``.

    Returns
    -------
    ndarray, shape (n + 1,)
        Monic polynomial with all roots of modulus <= ``radius``.
    """
    if len(poly) <= 1:
        return np.asarray(poly, dtype=float)
    roots = np.roots(poly)
    mod = np.abs(roots)
    if np.all(mod <= radius):
        return np.asarray(poly, dtype=float)
    roots = np.where(mod > 1.0, 1.0 / np.conj(roots), roots)
    mod = np.abs(roots)
    roots = np.where(mod > radius, roots * radius / np.maximum(mod, 1e-300), roots)
    return np.real(np.poly(roots))


def shift(x: np.ndarray, k: int) -> np.ndarray:
    """Return ``x(t - k)`` with zeros before the start, same shape as ``x`` (axis 0).

    Parameters
    ----------
    x : ndarray, shape (N, ...)
        Signal.
    k : int
        Delay in samples (>= 0).
    """
    if k == 0:
        return x.copy()
    out = np.zeros_like(x)
    out[k:] = x[:-k]
    return out


Normal = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def from_jacobian(gradient: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Normal:
    """Wrap ``(theta, e) -> psi`` (N, p) as ``(theta, e) -> (psi^T psi, psi^T e)``.

    Parameters
    ----------
    gradient : callable
        ``(theta, e) -> psi`` (N, p).
    """

    def normal(theta: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        psi = gradient(theta, e)
        return psi.T @ psi, psi.T @ e

    return normal


def levenberg_marquardt(
    theta0: np.ndarray,
    errors: Callable[[np.ndarray], np.ndarray],
    normal: Normal,
    project: Callable[[np.ndarray], np.ndarray] | None = None,
    max_iter: int = 50,
    tol: float | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> PemResult:
    """Minimize ``||e(theta)||^2`` by damped Gauss-Newton steps.

    Parameters
    ----------
    theta0 : ndarray, shape (p,)
        Initial estimate (must give finite errors).
    errors : callable
        ``theta -> e``, shape (N,).
    normal : callable
        ``(theta, e) -> (H, g)`` with ``H = psi^T psi`` (p, p) and ``g = psi^T e``
        (p,), ``psi = -de/dtheta``.
    project : callable, optional
        Maps a trial parameter vector into the admissible set.
    max_iter : int
        Maximum number of steps.
    tol : float, optional
        Stop when the relative loss decrease (achieved, or predicted by the
        Gauss-Newton model) is below ``tol``.  Default ``1e-3 / N``: a step
        that changes the loss by less moves the parameters by less than about
        0.03 of their standard deviations, i.e. statistically nothing.
    progress : callable, optional
        Called after every step with the step count and the current loss
        ``e^T e / N`` (for a progress display).

    Returns
    -------
    PemResult
        Minimizer, covariance and loss.
    """
    theta = np.asarray(theta0, dtype=float).copy()
    if project is not None:
        theta = project(theta)
    e = errors(theta)
    V = float(e @ e)
    H, g = normal(theta, e)
    tol = 1e-3 / max(e.shape[0], 1) if tol is None else float(tol)
    mu = 1e-4
    iterations = 0
    p = theta.size
    converged = False
    while iterations < max_iter and p:
        iterations += 1
        if progress is not None:
            progress(iterations, V / max(e.shape[0], 1))
        diag = np.diag(H).copy()
        diag[diag <= 0] = 1.0
        try:
            step = np.linalg.solve(H + mu * np.diag(diag), g)
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(H + mu * np.diag(diag), g, rcond=None)[0]
        if float(g @ step) < tol * V:  # predicted improvement negligible: converged
            converged = True
            break
        trial = theta + step
        if project is not None:
            trial = project(trial)
        e_new = errors(trial)
        V_new = float(e_new @ e_new) if np.all(np.isfinite(e_new)) else np.inf
        if V_new < V:
            decrease = (V - V_new) / max(V, 1e-300)
            theta, e, V = trial, e_new, V_new
            H, g = normal(theta, e)
            mu = max(mu / 10.0, 1e-12)
            if decrease < tol:
                converged = True
                break
        else:
            mu *= 10.0
            if mu > 1e8:  # no descent direction left: a (local) minimum
                converged = True
                break
    N = e.shape[0]
    lam = V / max(1, N - p)
    try:
        cov = lam * np.linalg.inv(H)
    except np.linalg.LinAlgError:
        cov = lam * np.linalg.pinv(H)
    converged = converged or not p or iterations < max_iter
    return PemResult(
        theta=theta, covariance=cov, loss=V / N, iterations=iterations, converged=converged
    )
