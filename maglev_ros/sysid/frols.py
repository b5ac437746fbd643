"""Forward regression with orthogonal least squares (FROLS) and an information criterion.

Billings' structure selection for linear-in-the-parameters models (S. A.
Billings, *Nonlinear System Identification*, Wiley 2013, sec. 3.4): among the
candidate regressors, the one with the largest error reduction ratio

``ERR_j = (w_j' y)^2 / ((w_j' w_j) (y' y))``

is taken, where ``w_j`` is candidate ``j`` orthogonalised (modified
Gram-Schmidt) against the regressors already taken; then the next, and so on.
The number of terms is the one minimising an information criterion of the
one-step residual variance ``s2(n)`` after ``n`` terms:

- ``'aic'``: ``N ln s2(n) + 2 n``;
- ``'bic'``: ``N ln s2(n) + n ln N`` (consistent: the default);
- ``'fpe'``: ``N ln s2(n) + N ln((N + n) / (N - n))``.

The parameters of the chosen terms are then re-estimated by ordinary least
squares on the original (not orthogonalised) regressors, with their covariance
``s2 (Phi' Phi)^-1``, ``s2 = |r|^2 / (N - n)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['CRITERIA', 'FrolsResult', 'frols']

CRITERIA = ('aic', 'bic', 'fpe')


@dataclass(frozen=True)
class FrolsResult:
    """Outcome of :func:`frols`.

    Attributes
    ----------
    selected : ndarray of int, shape (n,)
        Indices of the chosen candidate columns, in the order taken.
    theta : ndarray, shape (n,)
        Least-squares parameters of the chosen columns.
    covariance : ndarray, shape (n, n)
        Parameter covariance ``s2 (Phi' Phi)^-1``.
    err : ndarray, shape (n_taken,)
        Error reduction ratio of every column taken before the criterion's
        choice (the first ``n`` are the selected ones).
    criterion : ndarray, shape (n_taken + 1,)
        Information criterion after 0, 1, ... terms.
    noise_variance : float
        Residual variance ``s2`` of the chosen model.
    """

    selected: np.ndarray
    theta: np.ndarray
    covariance: np.ndarray
    err: np.ndarray
    criterion: np.ndarray
    noise_variance: float


def _penalty(kind: str, N: int, n: np.ndarray) -> np.ndarray:
    if kind == 'aic':
        return 2.0 * n
    if kind == 'bic':
        return n * np.log(N)
    if kind == 'fpe':
        return N * np.log((N + n) / np.maximum(N - n, 1))
    raise ValueError(f'criterion must be one of {CRITERIA}, got {kind!r}')


def frols(
    candidates: np.ndarray,
    target: np.ndarray,
    max_terms: int = 30,
    criterion: str = 'bic',
    n_terms: int | None = None,
) -> FrolsResult:
    """Choose regressors by FROLS and an information criterion, then fit them.

    Parameters
    ----------
    candidates : ndarray, shape (N, M)
        Candidate regressor columns.
    target : ndarray, shape (N,)
        Regressand.
    max_terms : int
        Most terms considered.
    criterion : {'bic', 'aic', 'fpe'}
        Information criterion choosing the number of terms.
    n_terms : int, optional
        Take exactly this many terms instead of the criterion's choice.

    Returns
    -------
    FrolsResult
        Chosen columns, parameters and covariance.
    """
    P = np.array(candidates, dtype=float, order='F')
    y = np.asarray(target, dtype=float).ravel()
    N, M = P.shape
    if y.shape[0] != N:
        raise ValueError(f'target has {y.shape[0]} samples, candidates {N}')
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(y))):
        raise ValueError('candidates or target contain NaN or infinite values')
    _penalty(criterion, N, np.zeros(1))  # validates the name
    limit = min(int(max_terms if n_terms is None else n_terms), M, N - 1)
    if limit < 1:
        raise ValueError(f'max_terms must be >= 1, got {max_terms!r}')
    yy = float(y @ y)
    if yy == 0.0:
        raise ValueError('the target is identically zero: nothing to explain')
    norms = np.einsum('ij,ij->j', P, P)
    alive = norms > 1e-300 * N
    r = y.copy()
    chosen: list[int] = []
    errs: list[float] = []
    rss = [yy]
    scale = np.sqrt(np.where(alive, norms, 1.0))  # column scale of the original candidates
    for _ in range(limit):
        wn = np.einsum('ij,ij->j', P, P)
        usable = alive & (wn > 1e-10 * scale**2)  # not (numerically) in the span already taken
        if not np.any(usable):
            break
        g = (P.T @ y) / np.where(usable, wn, 1.0)
        err = np.where(usable, g**2 * wn / yy, -1.0)
        j = int(np.argmax(err))
        w = P[:, j].copy()
        chosen.append(j)
        errs.append(float(err[j]))
        r -= g[j] * w
        rss.append(float(r @ r))
        alive[j] = False
        P -= np.outer(w, (w @ P) / wn[j])  # modified Gram-Schmidt against the new column
    n = np.arange(len(rss), dtype=float)
    s2 = np.maximum(np.asarray(rss), 1e-300 * yy) / N
    crit = N * np.log(s2) + _penalty(criterion, N, n)
    best = len(chosen) if n_terms is not None else max(1, int(np.argmin(crit)))
    selected = np.asarray(chosen[:best], dtype=int)
    Phi = np.asarray(candidates, dtype=float)[:, selected]
    theta, *_ = np.linalg.lstsq(Phi, y, rcond=None)
    resid = y - Phi @ theta
    dof = max(N - len(selected), 1)
    noise = float(resid @ resid) / dof
    covariance = noise * np.linalg.pinv(Phi.T @ Phi)
    return FrolsResult(
        selected=selected,
        theta=theta,
        covariance=covariance,
        err=np.asarray(errs),
        criterion=crit,
        noise_variance=noise,
    )
