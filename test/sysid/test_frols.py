"""FROLS: term order by error reduction, criteria, refusals."""

import numpy as np
import pytest

from maglev_ros.sysid.frols import frols


def regression(seed=0, N=2000):
    rng = np.random.default_rng(seed)
    P = rng.standard_normal((N, 8))
    y = 3.0 * P[:, 2] - 1.0 * P[:, 5] + 0.3 * P[:, 0] + 0.05 * rng.standard_normal(N)
    return P, y


@pytest.mark.parametrize('criterion', ['bic', 'aic', 'fpe'])
def test_terms_in_order_of_error_reduction(criterion):
    P, y = regression()
    result = frols(P, y, criterion=criterion)
    assert list(result.selected[:3]) == [2, 5, 0]
    np.testing.assert_allclose(result.theta[:3], [3.0, -1.0, 0.3], atol=5 * np.sqrt(
        np.diag(result.covariance))[:3].max())  # fmt: skip
    assert np.all(np.diff(result.err[:3]) < 0) and result.err.sum() <= 1.0 + 1e-12
    if criterion == 'bic':
        assert len(result.selected) == 3


def test_scaling_a_column_changes_nothing_but_its_parameter():
    P, y = regression(1)
    scaled = P.copy()
    scaled[:, 5] *= 1e4
    a, b = frols(P, y), frols(scaled, y)
    assert list(a.selected) == list(b.selected)
    np.testing.assert_allclose(b.theta[1] * 1e4, a.theta[1], rtol=1e-9)


def test_fixed_number_of_terms_and_collinear_candidates():
    P, y = regression(2)
    twin = np.column_stack([P, P[:, 2]])  # a copy of the best column is never taken twice
    result = frols(twin, y, n_terms=5)
    assert len(result.selected) == 5 and not {2, 8} <= set(result.selected)


def test_refusals():
    P, y = regression()
    with pytest.raises(ValueError, match='criterion must be one of'):
        frols(P, y, criterion='hqc')
    with pytest.raises(ValueError, match='identically zero'):
        frols(P, np.zeros(len(y)))
    with pytest.raises(ValueError, match='NaN or infinite'):
        frols(np.where(P > 3, np.nan, P), y)
    with pytest.raises(ValueError, match='target has 10 samples'):
        frols(P, y[:10])
