"""Quality measures with the toolbox's definitions: fit percentage, MSE, FPE, AIC, MDL."""

from __future__ import annotations

import numpy as np

__all__ = ['aic', 'fit_percent', 'fpe', 'loss_determinant', 'mdl']


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """Return the toolbox's normalized fit ``100 (1 - ||y - yhat|| / ||y - mean(y)||)``.

    Parameters
    ----------
    y, yhat : array_like, shape (N, ny) or (N,)
        Measured and model outputs.

    Returns
    -------
    ndarray, shape (ny,)
        Fit in percent per output (``-inf`` if an output is constant, or the
        model's output diverges).
    """
    y = np.asarray(y, dtype=float)
    yhat = np.asarray(yhat, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if yhat.ndim == 1:
        yhat = yhat[:, None]
    if y.shape != yhat.shape:
        raise ValueError(f'y has shape {y.shape} but yhat has shape {yhat.shape}')
    r = y - yhat
    c = y - np.ones(y.shape[0]) @ y / y.shape[0]
    # a diverging simulation (an unstable model) overflows to inf: its fit is -inf
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        num = np.sqrt(np.diag(r.T @ r))  # column norms through BLAS, fast in any memory order
        den = np.sqrt(np.diag(c.T @ c))
        return 100.0 * (1.0 - num / den)


def loss_determinant(e: np.ndarray) -> float:
    """Return ``det(E^T E / N)`` of residuals ``e`` (N, ny): the toolbox's loss ``V``.

    Parameters
    ----------
    e : ndarray, shape (N, ny)
        Residuals.
    """
    e = np.atleast_2d(np.asarray(e, dtype=float).T).T
    return float(np.linalg.det(e.T @ e / e.shape[0]))


def fpe(e: np.ndarray, n_params: int) -> float:
    """Akaike's final prediction error ``V (1 + d/N) / (1 - d/N)``.

    Parameters
    ----------
    e : ndarray, shape (N, ny)
        Prediction errors on estimation data.
    n_params : int
        Number of estimated parameters ``d``.

    Returns
    -------
    float
        FPE (``inf`` when ``d >= N``).
    """
    N = np.asarray(e).shape[0]
    if n_params >= N:
        return float('inf')
    return loss_determinant(e) * (1 + n_params / N) / (1 - n_params / N)


def aic(e: np.ndarray, n_params: int) -> float:
    """Akaike's information criterion ``N log V + 2 d + N ny (log 2 pi + 1)`` (the toolbox's).

    Parameters
    ----------
    e : ndarray, shape (N, ny)
        Residuals.
    n_params : int
        Number of estimated parameters d.
    """
    e = np.atleast_2d(np.asarray(e, dtype=float).T).T
    N, ny = e.shape
    return float(N * np.log(loss_determinant(e)) + 2 * n_params + N * ny * (np.log(2 * np.pi) + 1))


def mdl(e: np.ndarray, n_params: int) -> float:
    """Rissanen's minimum description length ``V (1 + d log(N) / N)`` (as ``selstruc``).

    Parameters
    ----------
    e : ndarray, shape (N, ny)
        Residuals.
    n_params : int
        Number of estimated parameters d.
    """
    N = np.asarray(e).shape[0]
    return loss_determinant(e) * (1 + n_params * np.log(N) / N)
