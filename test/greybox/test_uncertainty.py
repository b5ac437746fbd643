"""Sandwich (Newey-West) standard deviations: honest where the white-noise ones are not."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_ros.greybox import calibrate_dynamic, parameter_vector
from maglev_ros.greybox.uncertainty import bartlett_lags, long_run_spread


def _problem(p):
    return SimpleNamespace(free=[SimpleNamespace(name=f'p{k}', scale=1.0) for k in range(p)])


def _ar1(rng, n, rho):
    e = rng.standard_normal(n)
    out = np.empty(n)
    out[0] = e[0]
    for t in range(1, n):
        out[t] = rho * out[t - 1] + np.sqrt(1 - rho**2) * e[t]
    return out


def test_long_run_spread_matches_the_monte_carlo_spread_of_a_slow_regression():
    # y = x theta + e with a slow regressor and AR(1) errors (rho 0.9): the white-noise
    # formula understates the spread about sqrt((1 + rho^2) / (1 - rho^2))-fold here
    rng = np.random.default_rng(0)
    n, rho = 2000, 0.9
    estimates, reported, white = [], [], []
    for _ in range(200):
        x = _ar1(rng, n, rho)[:, None]
        e = _ar1(rng, n, rho)
        theta = float(np.linalg.lstsq(x, x[:, 0] + e, rcond=None)[0][0])
        r = x[:, 0] + e - x[:, 0] * theta
        s2 = float(r @ r) / (n - 1)
        spread = long_run_spread(_problem(1), -x, r, [n], 1, s2)
        estimates.append(theta)
        reported.append(spread.spread.std['p0'])
        white.append(spread.white.std['p0'])
    actual = float(np.std(estimates))
    assert 0.8 < np.median(reported) / actual < 1.2, (np.median(reported), actual)
    assert np.median(white) / actual < 0.5  # what was reported before
    assert bartlett_lags(rng.standard_normal((n, 1))) <= 3  # white scores: a short window


def test_channels_and_records_are_summed_per_sample():
    rng = np.random.default_rng(1)
    jac = rng.standard_normal((600, 2))
    r = rng.standard_normal(600)
    one = long_run_spread(_problem(2), jac, r, [200], 3, 1.0)
    two = long_run_spread(_problem(2), jac, r, [100, 100], 3, 1.0)
    assert one.lags >= 1 and two.lags >= 1
    assert one.spread.std['p0'] == pytest.approx(two.spread.std['p0'], rel=0.3)
    assert one.inflation['p0'] == pytest.approx(one.spread.std['p0'] / one.white.std['p0'])


def test_a_nominal_plant_lies_within_three_reported_sigma():
    """The benchmark's check (benchmarks/calibration_uncertainty.py), one seed, 1.6 s."""
    from maglev_ros.control.closed_loop import make_closed_loop
    from maglev_ros.excitation.signals import random_binary
    from maglev_ros.greybox import LevitationExperiment
    from maglev_ros.physics import load_parameters

    base = load_parameters('maggy_v2')
    n = 8000
    excitation = np.column_stack(
        [random_binary(n, 0.05, (0.0, 0.2), seed=70 + j) for j in range(4)]
    )
    result = make_closed_loop(base, plant=base, seed=7).run(n * 2e-4, excitation=excitation)
    assert not result.crashed, result.reason
    exp = LevitationExperiment(result.currents, result.readings, 'nominal plant', 2e-4)
    free = ('magnet.mass', 'magnet.polarization')
    vector = parameter_vector(base).with_free(free)
    cal = calibrate_dynamic(vector, [exp])
    for name in free:
        error = abs(cal.estimate[name] - vector[name].nominal)
        assert error <= 3 * cal.std[name], (name, error, cal.std[name])
        # the reported spread holds the white one and the numerical check
        assert cal.std[name] >= 0.9 * cal.std_white[name]
        assert cal.std[name] >= cal.std_numerical[name]
    assert cal.hac_lags >= 1
