import numpy as np
import pytest
from scipy.signal import lfilter

from maglev_ros.sysid.filters import inverse_filter


def test_inverse_filter_equals_lfilter():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((3, 500))
    c = np.array([1.0, -0.5, 0.2, 0.1])
    assert np.allclose(inverse_filter(c, x), lfilter([1.0], c, x, axis=1), atol=1e-13)
    assert np.allclose(inverse_filter(c, x[0]), lfilter([1.0], c, x[0]), atol=1e-13)
    assert np.array_equal(inverse_filter(np.ones(1), x[1]), x[1])


def test_inverse_filter_needs_monic_polynomial():
    with pytest.raises(ValueError, match='c must be a monic'):
        inverse_filter(np.array([2.0, 1.0]), np.zeros(5))
