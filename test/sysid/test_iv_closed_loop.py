"""IV with external instruments in closed loop: consistent where ARX and input-based IV are not."""

import numpy as np
import pytest

from maglev_ros.sysid import arx, iv4

from .closed_loop import THETA_CL, simulate_loop


def relative_error(theta):
    return float(np.linalg.norm(theta - THETA_CL) / np.linalg.norm(THETA_CL))


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_excitation_instruments_remove_the_feedback_bias(seed):
    data, r = simulate_loop(20000, seed)
    direct = arx(data, 2, 2, 1)
    input_iv = iv4(data, 2, 2, 1)
    external = iv4(data, 2, 2, 1, instruments=r)
    # direct ARX: ~33 % off; input-based IV4: ~3 %; IV on r: < 1 %, within 3 sigma
    assert relative_error(direct.theta) > 0.25
    assert relative_error(input_iv.theta) > 0.015
    assert relative_error(external.theta) < 0.012
    assert np.all(np.abs(external.theta - THETA_CL) < 3.5 * external.std)
    assert 'external instrument' in external.report.method


def test_excitation_instruments_several_experiments_and_refine():
    (d1, r1), (d2, r2) = simulate_loop(10000, 3), simulate_loop(10000, 4)
    model = iv4([d1, d2], 2, 2, 1, instruments=[r1, r2], refine=1)
    assert relative_error(model.theta) < 0.012
    # a 2-D (N, 1) instrument array gives the same as a 1-D one
    one = iv4(d1, 2, 2, 1, instruments=r1)
    np.testing.assert_allclose(iv4(d1, 2, 2, 1, instruments=r1[:, None]).theta, one.theta)


@pytest.mark.parametrize(
    ('make', 'match'),
    [
        (lambda r: r[:-1], r'must have shape \(4000,\)'),
        (lambda r: np.where(np.arange(r.size) == 7, np.nan, r), 'NaN or infinite'),
        (lambda r: 0 * r, 'all zero'),
    ],
)
def test_bad_instruments_name_the_problem(make, match):
    data, r = simulate_loop(4000, 5)
    with pytest.raises(ValueError, match=match):
        iv4(data, 2, 2, 1, instruments=make(r))


def test_band_limited_excitation_gets_enough_delays():
    """A slow PRBS (levels held 6 samples): 4 delays span too few directions; more are used."""
    data, r = simulate_loop(30000, 6, hold=6)
    model = iv4(data, 2, 2, 1, instruments=r)
    assert relative_error(model.theta) < 0.03
    assert relative_error(arx(data, 2, 2, 1).theta) > 0.2
