"""Fast all-pole filtering ``x / C(q)`` for the prediction-error iterations.

``scipy.signal.lfilter`` is general (any numerator, any dtype, any axis) and
costs ~8 ns per sample and coefficient here; the Gauss-Newton loops of ARMAX
filter several 25,000-sample signals by ``1 / C`` in every iteration, so a
compiled special case (monic denominator, float64 rows) pays off.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ['inverse_filter']


@njit(cache=True)
def _inverse_rows(c: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    n = c.shape[0]
    for r in range(x.shape[0]):
        for t in range(x.shape[1]):
            acc = x[r, t]
            for k in range(1, min(n, t + 1)):
                acc -= c[k] * out[r, t - k]
            out[r, t] = acc


def inverse_filter(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Filter each row of ``x`` by ``1 / C(q)`` with zero initial state.

    Parameters
    ----------
    c : ndarray, shape (n + 1,)
        Monic denominator ``[1, c1, ..., cn]`` in powers of ``q^-1``.
    x : ndarray, shape (N,) or (rows, N)
        Signals along the last axis.

    Returns
    -------
    ndarray
        Same shape as ``x``; equals ``scipy.signal.lfilter([1], c, x)``.
    """
    c = np.asarray(c, dtype=float)
    if c.ndim != 1 or c.shape[0] == 0 or c[0] != 1.0:
        raise ValueError(f'c must be a monic 1-D polynomial [1, c1, ...], got {c!r}')
    x = np.asarray(x, dtype=float)
    rows = np.ascontiguousarray(x.reshape(-1, x.shape[-1]) if x.ndim > 1 else x[None, :])
    out = np.empty_like(rows)
    _inverse_rows(c, rows, out)
    return out.reshape(x.shape)
