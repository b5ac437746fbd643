"""Normal equations from lagged correlations, without forming the regression matrix.

A regression matrix of lagged signals, ``Phi[t - start, k] = s * x(t - lag_k)``,
has cross-products ``sum_t x(t - i) z(t - j)`` that are (windowed)
correlations.  Along a diagonal of the product matrix both lags grow by one,
so each entry follows from its neighbour by adding the sample that enters the
window and removing the one that leaves it::

    S(i+1, j+1) = S(i, j) + x(start-i-1) z(start-j-1) - x(N-1-i) z(N-1-j)

Only the first entry of each diagonal needs a full dot product (BLAS ``ddot``),
so ``Phi^T Phi`` for ``p`` regressors costs about ``p`` dot products of length
``N`` (upper triangle of a symmetric product, then mirrored) instead of
``N p^2`` multiply-adds plus an ``N x p`` copy - and no large temporary array
is allocated.  The result is exact (up to rounding),
not the biased/windowed correlation estimate.

A *block* is a row ``(signal index, first lag, count, sign)``; a regressor set
is an ``(n_blocks, 4)`` integer array.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ['block_sizes', 'lag_gram']


def block_sizes(blocks: np.ndarray) -> int:
    """Return the number of regressors described by ``blocks`` (sum of counts).

    Parameters
    ----------
    blocks : ndarray
        Regressor blocks, one row each with its count.
    """
    return int(np.asarray(blocks)[:, 2].sum()) if len(blocks) else 0


@njit(cache=True)
def _block_pair(
    x: np.ndarray,
    lx: int,
    nx: int,
    z: np.ndarray,
    lz: int,
    nz: int,
    start: int,
    out: np.ndarray,
    r0: int,
    c0: int,
    sign: float,
    upper_only: bool,
) -> None:  # pragma: no cover - numba
    N = x.shape[0]
    first = 0 if upper_only else -(nx - 1)
    for d in range(first, nz):  # diagonal: column index - row index
        k = 0 if d >= 0 else -d
        m = k + d
        i = lx + k
        j = lz + m
        acc = np.dot(x[start - i : N - i], z[start - j : N - j])
        out[r0 + k, c0 + m] = sign * acc
        while k + 1 < nx and m + 1 < nz:
            acc += x[start - i - 1] * z[start - j - 1] - x[N - 1 - i] * z[N - 1 - j]
            k += 1
            m += 1
            i += 1
            j += 1
            out[r0 + k, c0 + m] = sign * acc


@njit(cache=True)
def _lag_gram(
    signals: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    start: int,
    out: np.ndarray,
    symmetric: bool,
) -> None:  # pragma: no cover - numba
    r0 = 0
    for a in range(left.shape[0]):
        c0 = 0
        for b in range(right.shape[0]):
            if left[a, 2] > 0 and right[b, 2] > 0 and (not symmetric or b >= a):
                _block_pair(
                    signals[left[a, 0]],
                    left[a, 1],
                    left[a, 2],
                    signals[right[b, 0]],
                    right[b, 1],
                    right[b, 2],
                    start,
                    out,
                    r0,
                    c0,
                    float(left[a, 3] * right[b, 3]),
                    symmetric and a == b,
                )
            c0 += right[b, 2]
        r0 += left[a, 2]
    if symmetric:  # mirror the computed upper triangle
        n = out.shape[0]
        for i in range(n):
            for j in range(i):
                out[i, j] = out[j, i]


def lag_gram(signals: np.ndarray, left: np.ndarray, right: np.ndarray, start: int) -> np.ndarray:
    """Cross-product ``Phi_left^T Phi_right`` of two lagged regressor sets.

    Parameters
    ----------
    signals : ndarray, shape (n_signals, N)
        Signals, one per row (C-contiguous).
    left, right : ndarray, shape (n_blocks, 4), int
        Regressor blocks ``(signal, first lag, count, sign)``: block columns are
        ``sign * signal(t - lag)`` for ``lag = first .. first + count - 1``.
    start : int
        First time index of the regression (>= every lag used).

    Returns
    -------
    ndarray, shape (p_left, p_right)
        ``sum_{t=start}^{N-1} phi_left(t) phi_right(t)^T``.
    """
    signals = np.ascontiguousarray(signals, dtype=float)
    left = np.ascontiguousarray(left, dtype=np.int64).reshape(-1, 4)
    right = np.ascontiguousarray(right, dtype=np.int64).reshape(-1, 4)
    for blocks in (left, right):
        if len(blocks) and np.any(blocks[:, 1] + np.maximum(blocks[:, 2], 1) - 1 > start):
            raise ValueError(f'start={start} is smaller than a lag in blocks {blocks.tolist()}')
    out = np.zeros((block_sizes(left), block_sizes(right)))
    symmetric = left.shape == right.shape and bool(np.array_equal(left, right))
    _lag_gram(signals, left, right, int(start), out, symmetric)
    return out
