"""Exact ZOH discretisation against scipy.signal.cont2discrete."""

import numpy as np
import pytest
from scipy.signal import cont2discrete

from maglev_ros.physics import linearize, zoh


def test_zoh_matches_cont2discrete(v2):
    lin = linearize(v2).reduced()
    ad, bd = zoh(lin.A, lin.B, 2e-4)
    ref = cont2discrete((lin.A, lin.B, lin.C, lin.D), 2e-4, method='zoh')
    assert np.allclose(ad, ref[0], rtol=1e-12, atol=1e-15)
    assert np.allclose(bd, ref[1], rtol=1e-12, atol=1e-18)


def test_zoh_validates():
    with pytest.raises(ValueError, match='dt must be positive'):
        zoh(np.eye(2), np.ones((2, 1)), 0.0)
    with pytest.raises(ValueError, match='A must be square'):
        zoh(np.ones((2, 3)), np.ones((2, 1)), 0.1)
