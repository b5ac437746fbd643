"""Consistency in the closed loop (a short run of benchmarks/estimator_consistency.py)."""

import dataclasses

import pytest
from scipy.stats import chi2

from maglev_ros.estimation import EstimatorConfig
from maglev_ros.estimation.consistency import ConsistencyResult, average_band, run_consistency


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
        angular_acceleration_noise=0.0,
    )
    r = run_consistency(v2, config, 1.5, linear=v2_linear)
    assert not r.crashed
    assert ConsistencyResult.verdict(r.nees, r.nees_band) == 'overconfident', r.nees
    assert not r.nees_ok
