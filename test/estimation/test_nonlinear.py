"""EKF and UKF: the full model against filterpy, the fast one within its own uncertainty."""

import numpy as np
import pytest

from maglev_ros.estimation import EstimatorConfig, EstimatorConfigError, make_estimator
from maglev_ros.estimation.base import Estimator
from maglev_ros.estimation.filter_model import magnet_reading
from maglev_ros.estimation.nonlinear_kernels import _wrench
from maglev_ros.estimation.reference import FilterpyReference
from maglev_ros.physics import kernels as phys
from maglev_ros.physics.linearization import FD_STEP


def _run(est, ref, ys, cs):
    """Reduced estimates and covariances, ours and the reference's: (N, 10), (N, n, n)."""
    ours, ours_p, theirs, theirs_p = [], [], [], []
    for y, c in zip(ys, cs, strict=True):
        ours.append((est.step(y, c) - est.x_eq)[est.reduced])
        ours_p.append(est.state_covariance)
        xr, pr = ref.step(y, c)
        theirs.append(xr[: est.n_reduced])
        theirs_p.append(pr)
    return np.array(ours), np.array(ours_p), np.array(theirs), np.array(theirs_p)


def test_the_reading_model_is_the_physics_reading(v2):
    est = make_estimator(v2, EstimatorConfig(filter='ekf'))
    src, coil, sens, mag, work = v2.measurement_arguments()
    rng = np.random.default_rng(2)
    x_eq = est.x_eq
    for _ in range(20):
        x = x_eq.copy()
        x[:3] += rng.normal(scale=2e-3, size=3)
        x[3:6] += rng.normal(scale=0.05, size=3)
        u = rng.normal(scale=0.5, size=4)
        want = phys.fast_measurement(x, u, src, coil, sens, mag, work)
        got = magnet_reading(x, u, *est.filter_model.h_args)
        assert np.max(np.abs(got - want)) < 1e-15 * 1e3 * np.max(np.abs(want))


@pytest.mark.parametrize('kind', ['ekf', 'ukf'])
@pytest.mark.parametrize(('delay', 'bias'), [(1, False), (0, False), (1, True)])
def test_the_full_model_agrees_with_filterpy(v2, v2_linear, v2_data, kind, delay, bias):
    ys, cs, _ = v2_data
    n = 300
    ys = ys[:n].copy()
    ys[[40, 41, 200]] = np.nan  # whole samples missing: predict only
    config = EstimatorConfig(
        filter=kind,
        prediction='full',
        sensor_delay=delay,
        bias_states=bias,
        gate_probability=1.0,
    )
    est = make_estimator(v2, config, linear=v2_linear)
    ref = FilterpyReference(make_estimator(v2, config, linear=v2_linear))
    x, p, xr, pr = _run(est, ref, ys, cs[:n])
    assert np.max(np.abs(x - xr)) / np.max(np.abs(xr)) < 1e-6
    assert np.max(np.abs(p - pr)) / np.max(np.abs(pr)) < 1e-6
    assert est.status().missing == (3, 3, 3)


@pytest.mark.parametrize('kind', ['ekf', 'ukf'])
def test_the_fast_prediction_stays_within_a_tenth_of_sigma_of_the_reference(
    v2, v2_linear, v2_data, kind
):
    ys, cs, _ = v2_data
    est = make_estimator(v2, EstimatorConfig(filter=kind), linear=v2_linear)
    ref = FilterpyReference(
        make_estimator(v2, EstimatorConfig(filter=kind, prediction='full'), linear=v2_linear)
    )
    x, _, xr, pr = _run(est, ref, ys, cs)
    sigma = np.sqrt(np.einsum('kii->ki', pr)[:, :10])
    worst = np.max(np.abs(x - xr) / sigma)
    assert worst < 0.1, worst
    assert np.max(np.abs(x - xr)) > 0  # a different model, not the same numbers


@pytest.mark.parametrize('kind', ['ekf', 'ukf'])
@pytest.mark.parametrize('delay', [1, 0])
def test_the_compiled_step_gives_the_numbers_of_the_python_step(
    v2, v2_linear, v2_data, kind, delay
):
    ys, cs, _ = v2_data
    ys, cs = ys[:400].copy(), cs[:400]
    ys[100:110, 0:3] = np.nan  # a missing sensor
    ys[150:180, 3:6] = ys[150, 3:6]  # a frozen sensor
    ys[250, 6:9] += 5e-3  # an outlier the gate rejects
    ys[300:360] = np.nan  # every reading lost: the filter restarts
    config = EstimatorConfig(filter=kind, sensor_delay=delay, lost_samples=50)
    fast = make_estimator(v2, config, linear=v2_linear)
    slow = make_estimator(v2, config, linear=v2_linear)
    for y, c in zip(ys, cs, strict=True):
        assert np.array_equal(fast.step(y, c), Estimator.step(slow, y, c))
        assert np.array_equal(fast.state_covariance, slow.state_covariance)
    assert fast.status() == slow.status()
    status = fast.status()
    assert status.rejected[2] >= 1 and status.missing[0] >= 10 and status.freeze_events[1] == 1
    assert status.restarts >= 1


def test_an_unknown_prediction_is_named():
    with pytest.raises(EstimatorConfigError, match='prediction must be one of fast, full'):
        EstimatorConfig(filter='ekf', prediction='euler')


def test_the_fast_ukf_takes_the_wrench_of_a_pose_from_its_jacobian_one_column_a_sample(
    v2, v2_linear, v2_data
):
    ys, cs, _ = v2_data
    est = make_estimator(v2, EstimatorConfig(filter='ukf', sensor_delay=0), linear=v2_linear)
    src, coil, rim, par, work = est._f_args
    # the first prediction: every column, at the posterior (published: no sensor delay)
    x0 = est.step(ys[0], cs[0])
    assert est._J.shape == (6, 5) and est._cursor[0] == 0
    first = est._J.copy()
    assert np.all(np.abs(first[:3, :3]).max(axis=0) > 0)  # the force moves with x, y, z
    for k in range(1, 6):  # one column a sample, in turn
        est.step(ys[k], cs[k])
        changed = np.flatnonzero(np.any(est._J != first, axis=0))
        assert set(changed) <= set(range(k)), (k, changed)
        assert est._cursor[0] == k % 5
    # each column is the forward difference of the wrench at a centre the filter held
    w0, _ = _wrench(x0, cs[0], src, coil, rim, par, work)
    xp = x0.copy()
    xp[0] += FD_STEP
    wp, _ = _wrench(xp, cs[0], src, coil, rim, par, work)
    np.testing.assert_allclose(first[:, 0], (wp - w0) / FD_STEP, rtol=1e-12, atol=0)
    est.reset()
    assert est._cursor[0] == -1  # all of it again after a reset
