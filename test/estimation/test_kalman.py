"""The linear KF against filterpy, gating, freezes, missing samples, covariance health."""

import dataclasses

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2

from maglev_ros.estimation import (
    EstimatorConfig,
    EstimatorConfigError,
    KalmanEstimator,
    make_estimator,
)
from maglev_ros.physics import make_model

from .open_loop import open_loop_run


def _filterpy_twin(est):
    kf = KalmanFilter(dim_x=est.n_states, dim_z=est.n_outputs, dim_u=est.n_inputs)
    kf.F, kf.B, kf.H, kf.Q = est.F.copy(), est.B.copy(), est.H.copy(), est.Q.copy()
    kf.R = np.diag(est.r_diag)
    kf.x = np.zeros(est.n_states)
    kf.P = est.initial_covariance()
    return kf


@pytest.mark.parametrize('delay', [1, 0])
@pytest.mark.parametrize('bias', [False, True])
def test_kf_agrees_with_filterpy(v2, v2_linear, v2_data, delay, bias):
    ys, cs, _ = v2_data
    ys = ys.copy()
    missing = [40, 41, 42, 300]
    ys[missing] = np.nan  # whole samples missing: predict only
    config = EstimatorConfig(sensor_delay=delay, bias_states=bias, gate_probability=1.0)
    est = KalmanEstimator(v2, config, linear=v2_linear)
    kf = _filterpy_twin(est)
    worst_x = worst_p = 0.0
    prev = None
    for k, (y, i) in enumerate(zip(ys, cs, strict=True)):
        out = est.step(y, i)
        held = i if (delay == 0 or prev is None) else prev
        z = est.measurement(y, held)
        kf.update(None if k in missing else z)
        if delay == 0:
            x_pub, p_pub = kf.x.copy(), kf.P.copy()
            kf.predict(u=i - est.u_eq)
        else:
            kf.predict(u=0.5 * (held + i) - est.u_eq)
            x_pub, p_pub = kf.x.copy(), kf.P.copy()
        prev = i
        dx = (out - est.x_eq)[est.reduced]
        worst_x = max(worst_x, np.max(np.abs(dx - x_pub[:10])) / np.max(np.abs(x_pub[:10])))
        worst_p = max(
            worst_p, np.max(np.abs(est.state_covariance - p_pub)) / np.max(np.abs(p_pub))
        )
    assert worst_x < 1e-9 and worst_p < 1e-9, (worst_x, worst_p)
    assert est.status().missing == (4, 4, 4)


def test_gate_rejects_an_outlier_of_one_sensor(v2, v2_linear, v2_data):
    ys, cs, xs = v2_data
    est = KalmanEstimator(v2, linear=v2_linear)
    for k in range(400):
        est.step(ys[k], cs[k])
    assert est.status().rejected == (0, 0, 0)
    bad = ys[400].copy()
    bad[3:6] += 2e-3  # sensor 1 off by 2 mT on every axis
    before = est.state
    est.step(bad, cs[400])
    assert est.last_accepted.tolist() == [True, False, True]
    assert est.last_nis_sensor[1] > chi2.ppf(0.99999, 3)
    assert est.status().rejected == (0, 1, 0)
    assert np.max(np.abs(est.state[:3] - before[:3])) < 5e-5


def test_a_frozen_sensor_is_missing_and_named(v2, v2_linear, v2_data):
    ys, cs, _ = v2_data
    est = KalmanEstimator(v2, EstimatorConfig(freeze_samples=4), linear=v2_linear)
    for k in range(300):
        est.step(ys[k], cs[k])
    base = est.status()
    stuck = ys[300, 6:9].copy()
    for k in range(300, 320):
        y = ys[k].copy()
        y[6:9] = stuck
        est.step(y, cs[k])
        if k >= 303:  # the 4th identical reading on
            assert est.status().frozen == (2,)
            assert not est.last_accepted[2] and est.last_accepted[0]
    status = est.status()
    assert status.frozen_names() == ('sensor_2',)
    assert status.missing[2] - base.missing[2] == 17
    assert status.freeze_events[2] - base.freeze_events[2] == 1
    est.step(ys[320], cs[320])
    assert est.status().frozen == ()


def test_covariance_stays_symmetric_positive_definite(v2, v2_linear, v2_data):
    ys, cs, _ = v2_data
    est = KalmanEstimator(v2, EstimatorConfig(bias_states=True), linear=v2_linear)
    rng = np.random.default_rng(0)
    for k in range(len(ys)):
        y = ys[k].copy()
        y[rng.random(9).reshape(3, 3).any(axis=1).repeat(3) & (rng.random() < 0.3)] = np.nan
        est.step(y, cs[k])
        p = est.state_covariance
        assert np.array_equal(p, p.T)
    assert np.min(np.linalg.eigvalsh(p)) > 0


@pytest.mark.parametrize('kind', ['ekf', 'ukf'])
def test_nonlinear_filters_agree_with_the_kf_near_the_equilibrium(v2, v2_linear, v2_data, kind):
    ys, cs, _ = v2_data
    n = 400 if kind == 'ekf' else 200
    kf = make_estimator(v2, EstimatorConfig(filter='kf'), linear=v2_linear)
    other = make_estimator(v2, EstimatorConfig(filter=kind), linear=v2_linear)
    for k in range(n):
        a = kf.step(ys[k], cs[k])
        b = other.step(ys[k], cs[k])
    sigma = kf.state_std()[:3]
    assert np.all(np.abs(a[:3] - b[:3]) < 0.2 * sigma)
    assert np.all(np.abs(other.state_std()[:3] - sigma) < 0.1 * sigma)


@pytest.mark.parametrize(
    ('changes', 'match'),
    [
        ({'filter': 'pf'}, 'filter must be one of kf, ekf, ukf'),
        ({'sensor_delay': 2}, 'sensor_delay must be 0 or 1'),
        ({'sensor_noise': -1.0}, 'sensor_noise must be a finite number > 0'),
        ({'freeze_samples': 1}, 'freeze_samples must be an integer >= 2'),
        ({'gate_probability': 0.2}, 'gate_probability must be in'),
    ],
)
def test_bad_settings_name_the_value(changes, match):
    with pytest.raises(EstimatorConfigError, match=match):
        EstimatorConfig(**changes)
    with pytest.raises(ValueError, match='unknown estimator setting'):
        EstimatorConfig.from_mapping({'sensor_nois': 1e-4})


@pytest.mark.parametrize('strength', [1.1, 0.9])
def test_the_magnet_strength_state_finds_a_polarisation_error(v2, v2_linear, strength):
    # the plant's magnet is stronger or weaker (and heavier or lighter: same equilibrium)
    p = v2.params
    magnet = dataclasses.replace(
        p.magnet, polarization=p.magnet.polarization * strength, mass=p.magnet.mass * strength
    )
    plant = make_model(p.replace(magnet=magnet, solenoid_radius_correction=v2.correction))
    ys, cs, xs = open_loop_run(plant, v2_linear.x_eq)
    est = KalmanEstimator(v2, EstimatorConfig(magnet_strength=True), linear=v2_linear)
    errors = [est.step(y, c)[:3] - x[:3] for y, c, x in zip(ys, cs, xs, strict=True)]
    assert abs(est.strength - (strength - 1.0)) < 0.005, est.strength
    late = np.array(errors[375:])
    assert np.all(np.sqrt(np.mean(late**2, axis=0)) < 2.5 * est.state_std()[:3])
    with pytest.raises(EstimatorConfigError, match='magnet_strength is supported by the kf'):
        EstimatorConfig(filter='ekf', magnet_strength=True)


@pytest.mark.parametrize('kind', ['kf', 'ekf'])
def test_a_lost_magnet_restarts_the_filter_instead_of_diverging(v2, v2_linear, kind):
    # the magnet lies on the base: every reading is far from the prediction and gated out
    lying = v2_linear.x_eq.copy()
    lying[[0, 1, 2, 3]] = [2e-3, 19e-3, 25e-3, -0.47]
    rng = np.random.default_rng(0)
    est = make_estimator(v2, EstimatorConfig(filter=kind, lost_samples=100), linear=v2_linear)
    for _ in range(1000):  # 0.2 s: predict-only, P grows e-fold every ~17 ms
        y = v2.measurement(lying, np.zeros(4)) + rng.normal(scale=1e-4, size=9)
        est.step(y, np.zeros(4))
        assert np.all(np.isfinite(est.state_covariance))
    status = est.status()
    assert status.restarts == 10 and status.unaccepted == 0
    assert sum(status.rejected) == 3000
    assert np.allclose(est.state_std()[:3], 1e-3)  # bounded: restarted from the prior


@pytest.mark.parametrize('delay', [1, 0])
def test_compiled_step_gives_the_numbers_of_the_python_step(v2, v2_linear, v2_data, delay):
    """KalmanEstimator.step (one compiled call) against Estimator.step (Python around kernels)."""
    from maglev_ros.estimation.base import Estimator

    ys, cs, _ = v2_data
    ys = ys.copy()  # 750 samples
    ys[100:110, 0:3] = np.nan  # a missing sensor
    ys[200:230, 3:6] = ys[200, 3:6]  # a frozen sensor
    ys[500, 6:9] += 5e-3  # an outlier the gate rejects
    ys[600:660] = np.nan  # every reading lost: the filter restarts
    config = EstimatorConfig(sensor_delay=delay, lost_samples=50)
    fast = KalmanEstimator(v2, config, linear=v2_linear)
    slow = KalmanEstimator(v2, config, linear=v2_linear)
    for y, c in zip(ys, cs, strict=True):
        x_fast = fast.step(y, c)
        x_slow = Estimator.step(slow, y, c)
        assert np.array_equal(x_fast, x_slow)
        assert np.array_equal(fast.state_covariance, slow.state_covariance)
    assert fast.status() == slow.status()
    status = fast.status()
    assert status.rejected[2] >= 1 and status.missing[0] >= 10 and status.freeze_events[1] == 1
    assert status.restarts >= 1


@pytest.mark.parametrize('strength', [False, True])
def test_step_many_gives_the_numbers_of_step(v2, v2_linear, v2_data, strength):
    """A burst at a time (step_many, one compiled call) against sample after sample."""
    ys, cs, _ = v2_data
    ys = ys.copy()
    ys[100:110, 0:3] = np.nan
    ys[200:230, 3:6] = ys[200, 3:6]
    ys[500, 6:9] += 5e-3
    ys[600:660] = np.nan  # a restart
    config = EstimatorConfig(lost_samples=50, magnet_strength=strength)
    many = KalmanEstimator(v2, config, linear=v2_linear)
    one = KalmanEstimator(v2, config, linear=v2_linear)
    bounds = [0, 1, 6, 107, 333, 334, 601, 680, len(ys)]  # bursts of 1 to 267 samples
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        x, p = many.step_many(ys[lo:hi], cs[lo:hi])
        for i in range(lo, hi):
            assert np.array_equal(x[i - lo], one.step(ys[i], cs[i]))
            assert np.array_equal(p[i - lo], one.state_covariance)
    assert many.status() == one.status()
    assert np.array_equal(many.state, one.state)
    assert many.status().restarts >= 1
    with pytest.raises(ValueError, match='finite'):
        many.step_many(ys[:3], np.full((3, 4), np.nan))
    with pytest.raises(ValueError, match='rows'):
        many.step_many(ys[:3], cs[:2])


def test_step_takes_lists_and_strided_rows_without_compiling_again(v2, v2_linear, v2_data):
    """The compiled step has one signature (float64 C arrays); other inputs are converted."""
    from maglev_ros.estimation.linear_kernels import kf_packed_step

    ys, cs, _ = v2_data
    arrays = KalmanEstimator(v2, EstimatorConfig(), linear=v2_linear)
    others = KalmanEstimator(v2, EstimatorConfig(), linear=v2_linear)
    wide = np.zeros((len(ys), 2 * ys.shape[1]))
    wide[:, ::2] = ys  # every row a strided view
    for k in range(50):
        x = arrays.step(np.ascontiguousarray(ys[k]), np.ascontiguousarray(cs[k]))
        y = wide[k, ::2] if k % 2 else list(ys[k])
        assert np.array_equal(others.step(y, [float(c) for c in cs[k]]), x)
    assert len(kf_packed_step.signatures) == 1
    with pytest.raises(ValueError, match='y must have 9 readings'):
        others.step(ys[0][:5], cs[0])
    with pytest.raises(ValueError, match='y must have 9 readings'):
        others.step(ys[:2], cs[0])
    with pytest.raises(ValueError, match='currents must be 4 finite numbers'):
        others.step(ys[0], [np.nan, 0.0, 0.0, 0.0])


def test_a_measured_board_feedthrough_goes_into_the_same_packed_model():
    """use_board: the board's filter rows take the measured pair feedthrough; the packed
    arrays the compiled step reads stay where they are; a raw-field KF refuses."""
    from maglev_ros.loop.v4x_pc_setup import board_model
    from maglev_ros.physics.board_processing import BoardProcessing

    model = board_model('maggy_v2', 0)
    est = make_estimator(model, EstimatorConfig(sample_rate=1000.0, measurement='board'))
    F, B, y_eq = est.F, est.B.copy(), est.y_eq.copy()
    pairs = BoardProcessing.model_pairs(model) + np.array([[2e-5, 0], [0, -3e-5], [0, 0]])
    est.use_board(BoardProcessing.from_model(model, pairs=pairs))
    assert est.F is F and np.array_equal(est.y_eq, y_eq)
    rows = slice(est.filter_start, est.n_states)
    changed = est.B[rows] - B[rows]  # filter states: the pair's direct field, per coil
    # x: more field per ampere of the x pair (x+ up, x- down), y: less per ampere of the y pair
    assert changed[0, 0] > 0 and changed[0, 1] == pytest.approx(-changed[0, 0])
    assert changed[1, 2] < 0 and changed[1, 3] == pytest.approx(-changed[1, 2])
    assert np.allclose(changed[0, 2:], 0.0) and np.allclose(changed[1, :2], 0.0)
    assert np.array_equal(est.B[: est.filter_start], B[: est.filter_start])  # the magnet's
    raw = make_estimator(model, EstimatorConfig(sample_rate=1000.0))
    with pytest.raises(ValueError, match="measurement is 'raw'"):
        raw.use_board(BoardProcessing.from_model(model))


def test_the_x_and_y_offsets_start_from_their_own_std():
    """initial_bias_xy: the x and y bias states and the board's x/y filter states;
    initial_bias: the z bias states (a magnet 10 % off moves Bz by a few mT)."""
    from maglev_ros.loop.v4x_pc_setup import board_model

    config = EstimatorConfig(
        sample_rate=1000.0,
        measurement='board',
        bias_states=True,
        initial_bias=2e-3,
        initial_bias_xy=1e-4,
    )
    est = make_estimator(board_model('maggy_v2', 0), config)
    std = np.sqrt(np.diag(est.initial_covariance()))
    assert std[est.bias_start : est.filter_start].tolist() == [1e-4, 1e-4, 2e-3]
    assert std[est.filter_start :].tolist() == [1e-4, 1e-4]
