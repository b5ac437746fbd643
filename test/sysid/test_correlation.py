import numpy as np
import pytest

from maglev_ros.sysid.correlation import lag_gram


def lagged_matrix(S, blocks, start):
    N = S.shape[1]
    cols = [
        sign * S[sig, start - lag : N - lag]
        for sig, first, count, sign in blocks
        for lag in range(first, first + count)
    ]
    return np.column_stack(cols)


def test_lag_gram_equals_explicit_products():
    rng = np.random.default_rng(0)
    S = rng.standard_normal((3, 400))
    left = np.array([[0, 1, 4, -1], [2, 0, 3, 1]])
    right = np.array([[1, 2, 5, 1], [0, 0, 1, 1], [2, 3, 2, -1]])
    start = 6
    expected = lagged_matrix(S, left, start).T @ lagged_matrix(S, right, start)
    assert np.allclose(lag_gram(S, left, right, start), expected, rtol=1e-12, atol=1e-10)


def test_lag_gram_rejects_lags_beyond_start():
    S = np.zeros((1, 50))
    with pytest.raises(ValueError, match='start=2 is smaller than a lag'):
        lag_gram(S, np.array([[0, 1, 3, 1]]), np.array([[0, 0, 1, 1]]), 2)


def test_symmetric_gram_is_mirrored_exactly():
    rng = np.random.default_rng(1)
    S = rng.standard_normal((2, 300))
    blocks = np.array([[0, 1, 3, -1], [1, 2, 4, 1]])
    G = lag_gram(S, blocks, blocks, 5)
    X = lagged_matrix(S, blocks, 5)
    assert np.allclose(G, X.T @ X, rtol=1e-12, atol=1e-10)
    assert np.array_equal(G, G.T)
