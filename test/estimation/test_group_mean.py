"""The mean of N readings over a sample as one linear measurement of its start; the KF on it."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_ros.estimation import EstimatorConfig, EstimatorConfigError, KalmanEstimator
from maglev_ros.estimation.group_mean import group_mean_model
from maglev_ros.physics.discretization import zoh


def _readings(lin, x0, du, dt, n):
    """The n readings over one sample of the linear model from ``x0`` with ``du`` held."""
    a_s, b_s = zoh(lin.A, lin.B, dt / n)
    x, out = x0.copy(), []
    for _ in range(n):
        out.append(lin.C @ x + lin.D @ du)
        x = a_s @ x + b_s @ du
    return np.array(out), x


def test_the_mean_of_a_groups_readings_is_c_bar_x_plus_d_bar_u(v2_linear):
    lin = v2_linear.reduced()
    rng = np.random.default_rng(0)
    x0 = rng.normal(scale=[1e-4] * 3 + [1e-3] * 2 + [1e-3] * 3 + [1e-2] * 2)
    du = rng.normal(scale=0.1, size=4)
    readings, _ = _readings(lin, x0, du, 1e-3, 5)
    c_bar, d_bar = group_mean_model(lin.A, lin.B, lin.C, lin.D, 1e-3, 5)
    np.testing.assert_allclose(c_bar @ x0 + d_bar @ du, readings.mean(axis=0), rtol=1e-9,
                               atol=1e-15)  # fmt: skip
    # not the reading of the group's start or end: the velocity moves the magnet over it
    assert np.abs(lin.C @ x0 + lin.D @ du - readings.mean(axis=0)).max() > 1e-7
    same = group_mean_model(lin.A, lin.B, lin.C, lin.D, 1e-3, 1)
    np.testing.assert_allclose(same[0], lin.C)
    np.testing.assert_allclose(same[1], lin.D)
    for bad in (0, 2.0, True):
        with pytest.raises(ValueError, match='readings per mean must be an integer >= 1'):
            group_mean_model(lin.A, lin.B, lin.C, lin.D, 1e-3, bad)


def _track(v2, v2_linear, average: int, samples: int = 40) -> np.ndarray:
    """Feed the means of 5 readings per 1 ms sample to a KF told ``average``; its errors, m."""
    lin = v2_linear.reduced()
    config = EstimatorConfig(
        sample_rate=1000.0, average=average, sensor_noise=1e-7, quantization=0.0
    )
    est = KalmanEstimator(v2, config, v2_linear)
    rng = np.random.default_rng(1)
    x = np.zeros(10)
    x[:3] = [2e-4, -1e-4, 5e-5]
    x[5:8] = [2e-3, 1e-3, 0.0]
    errors = []
    for _ in range(samples):
        du = rng.normal(scale=0.05, size=4)
        readings, x = _readings(lin, x, du, 1e-3, 5)
        estimate = est.step(lin.y_eq + readings.mean(axis=0), lin.u_eq + du)
        errors.append(estimate[est.reduced[:3]] - (lin.x_eq[est.reduced[:3]] + x[:3]))
    return np.abs(np.array(errors[-10:])).max(axis=0)


def test_the_kf_told_the_group_tracks_the_state_at_the_samples_stamp(v2, v2_linear):
    # noise-free means of the linear model: the KF that models the mean converges
    # on the state at the group's end; one that reads it as a single reading lags
    told = _track(v2, v2_linear, 5)
    plain = _track(v2, v2_linear, 1)
    assert told.max() < 1e-9, told
    assert plain.max() > 10 * told.max(), (plain, told)


@pytest.mark.parametrize(
    'settings',
    [{'filter': 'ekf'}, {'filter': 'ukf'}, {'measurement': 'board'}, {'sensor_delay': 0},
     {'magnet_strength': True}],
)  # fmt: skip
def test_a_mean_of_readings_outside_the_kf_on_raw_delayed_readings_is_refused(settings):
    with pytest.raises(EstimatorConfigError, match=r'average 5 \(a mean of readings per sample\) '
                       'is supported by the kf filter'):  # fmt: skip
        EstimatorConfig(average=5, **settings)
    assert EstimatorConfig(average=5).measurement_variance == pytest.approx(
        EstimatorConfig().measurement_variance / 5
    )
