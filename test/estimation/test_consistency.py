"""Consistency in the closed loop (a short run of benchmarks/estimator_consistency.py)."""

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from maglev_ros.estimation import EstimatorConfig, KalmanEstimator
from maglev_ros.estimation.consistency import (
    ConsistencyResult,
    average_band,
    correlation_time,
    matched_config,
    prediction_errors,
    run_consistency,
    steady_covariance,
)


def test_average_band_is_the_chi_square_band_of_the_mean():
    low, high = average_band(30, 3)
    assert low == pytest.approx(chi2.ppf(0.025, 30) / 3)
    assert high == pytest.approx(chi2.ppf(0.975, 30) / 3)
    with pytest.raises(ValueError, match='need samples >= 1'):
        average_band(10, 0)


@pytest.mark.parametrize('kind', ['kf', 'ekf', 'ukf'])
def test_the_default_filters_are_not_overconfident(v2, v2_linear, kind):
    # 1.5 s of levitation with the lab's noise, the LQR in the loop
    r = run_consistency(v2, EstimatorConfig(filter=kind), 1.5, linear=v2_linear)
    assert not r.crashed
    assert r.samples == 5000
    assert r.nis_ok, (r.nis, r.nis_band)  # innovations: consistent
    assert r.nees <= r.nees_band[1], (r.nees, r.nees_band)  # errors: not above the band
    assert ConsistencyResult.verdict(r.nees, r.nees_band) in ('ok', 'conservative')


def test_a_filter_without_process_noise_is_found_overconfident(v2, v2_linear):
    config = dataclasses.replace(
        EstimatorConfig(),
        current_noise=1e-4,
        acceleration_noise=0.0,
        vertical_acceleration_noise=0.0,
        angular_acceleration_noise=0.0,
    )
    r = run_consistency(v2, config, 1.5, linear=v2_linear)
    assert not r.crashed
    assert ConsistencyResult.verdict(r.nees, r.nees_band) == 'overconfident', r.nees
    assert not r.nees_ok


def test_correlation_time_of_white_and_of_correlated_samples():
    rng = np.random.default_rng(1)
    white = rng.normal(size=20000)
    assert 0.8 < correlation_time(white) < 1.25
    phi = 0.9  # AR(1): tau = (1 + phi) / (1 - phi) = 19
    ar = np.empty_like(white)
    ar[0] = white[0]
    for k in range(1, len(ar)):
        ar[k] = phi * ar[k - 1] + white[k]
    assert 19 * 0.75 < correlation_time(ar) < 19 * 1.25
    assert correlation_time(np.ones(10)) == 1.0
    # an effective count may be fractional
    low, high = average_band(10 * 2.5, 2.5)
    assert low == pytest.approx(chi2.ppf(0.025, 25) / 2.5)


@pytest.mark.parametrize('kind', ['kf', 'ekf', 'ukf'])
def test_the_matched_filters_innovations_are_consistent(v2, v2_linear, kind):
    # 3 s of levitation with the lab's noise from the steady-state covariance:
    # the NIS in its band over every sample, the NEES not above its band over
    # the effective sample count (the errors are correlated over many samples)
    r = run_consistency(v2, matched_config('maggy_v2', kind), 3.0, linear=v2_linear)
    assert not r.crashed
    assert r.nees_correlation > 10
    assert r.nis_ok, (r.nis, r.nis_band)
    assert r.nees <= r.nees_band[1], (r.nees, r.nees_band)
    if kind == 'kf':  # the KF: inside the band (the EKF and UKF stay conservative on V2)
        assert r.nees_ok, (r.nees, r.nees_band)
    with pytest.raises(ValueError, match='no matched process noise'):
        matched_config('maggy_v9', kind)


def test_the_steady_covariance_is_the_filters_fixed_point(v2, v2_linear):
    config = matched_config('maggy_v2', 'kf', sensor_delay=0)
    est = KalmanEstimator(v2, config, linear=v2_linear)
    p = steady_covariance(v2, config, v2_linear)
    # one update with every reading, then one prediction: the same covariance
    s = est.H @ p @ est.H.T + np.diag(est.r_diag)
    k = p @ est.H.T @ np.linalg.inv(s)
    ikh = np.eye(len(p)) - k @ est.H
    posterior = ikh @ p @ ikh.T + k @ np.diag(est.r_diag) @ k.T
    predicted = est.F @ posterior @ est.F.T + est.Q
    assert np.max(np.abs(predicted - p)) <= 1e-9 * np.max(np.abs(p))
    with pytest.raises(ValueError, match="start must be 'steady' or 'prior'"):
        run_consistency(v2, config, 1.5, linear=v2_linear, start='zero')


def test_the_model_error_is_the_coil_currents_seen_through_b(v2, v2_linear):
    # the KF's one-step prediction error on the true plant: x, beta, vx and wy move
    # together (one horizontal current error through B), as do y, alpha, vy and wx;
    # z is a slow drift (its mean far from zero); what the matched tuning says
    w = prediction_errors(v2, 'kf', 1.5, linear=v2_linear)
    assert w.shape == (5000 - 1, 10)
    corr = np.corrcoef(w.T)
    x, y, z, a, b, vx, vy, vz, wx, wy = range(10)
    for i, j in ((x, b), (x, vx), (b, vx), (y, a), (y, vy), (a, vy)):
        assert abs(corr[i, j]) > 0.8, (i, j, corr[i, j])
    assert abs(corr[x, wy]) > 0.5 and abs(corr[y, wx]) > 0.5
    assert abs(corr[x, y]) < 0.2 and abs(corr[vx, vz]) < 0.2
    assert abs(w[:, vz].mean()) > 0.3 * w[:, vz].std()
    z_tau = correlation_time(w[:, z] - w[:, z].mean())
    assert z_tau > 2 * correlation_time(w[:, x] - w[:, x].mean())
