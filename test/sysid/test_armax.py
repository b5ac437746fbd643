import numpy as np
import pytest

from maglev_ros.sysid import OrderError, armax, arx

from .systems import (
    A2,
    B2,
    C_ARMAX,
    C_COLORED,
    mean_error,
    mimo_armax_truth,
    simulate_mimo_armax,
    simulate_siso,
)


def test_siso_armax_converges_like_one_over_sqrt_n():
    truth = np.concatenate([A2[1:], B2[1:], C_ARMAX[1:]])
    errors = mean_error(
        lambda N, s: armax(simulate_siso(N, s, C=C_ARMAX, noise=0.5), 2, 2, 1, 1).theta,
        [1000, 16000],
        [0, 1, 2],
        truth,
    )
    assert 0.1 < errors[1] / errors[0] < 0.5


def test_armax_removes_arx_bias_and_keeps_c_minimum_phase():
    data = simulate_siso(20000, 5, C=C_COLORED, noise=0.5)
    truth = np.concatenate([A2[1:], B2[1:], C_COLORED[1:]])
    model = armax(data, 2, 2, 2, 1)
    assert np.all(np.abs(model.theta - truth) < 5 * model.std)
    err_arx = np.linalg.norm(arx(data, 2, 2, 1).theta - truth[:4])
    assert np.linalg.norm(model.theta[:4] - truth[:4]) < 0.1 * err_arx
    assert np.all(np.abs(np.roots(model.polynomial('C'))) < 1)
    assert model.report.iterations >= 1


def test_mimo_armax_diagonal_c_converges():
    na, nb, nc = [[2, 2], [0, 2]], [[1, 1], [0, 1]], [1, 1]
    truth = mimo_armax_truth()
    errors = mean_error(
        lambda N, s: armax(simulate_mimo_armax(N, s), na, nb, nc, 1).theta,
        [1500, 24000],
        [0, 1],
        truth,
    )
    assert errors[1] < 0.45 * errors[0]
    model = armax(simulate_mimo_armax(24000, 9), na, nb, nc, 1)
    assert np.all(np.abs(model.theta - truth) < 5 * model.std)
    assert model.C.shape == (2, 2)


def test_armax_order_errors():
    data = simulate_mimo_armax(500, 0)
    with pytest.raises(OrderError, match=r'nc must be a scalar or have shape \(2,\)'):
        armax(data, 1, 1, [1, 1, 1])
    with pytest.raises(ValueError, match='fewer samples than parameters'):
        armax(simulate_siso(20, 0), 5, 5, 5)


def test_multi_experiment_estimators_use_all_data():
    from maglev_ros.sysid import iv4, merge, oe

    d1 = simulate_siso(4000, 1, C=C_ARMAX, noise=0.5)
    d2 = simulate_siso(3000, 2, C=C_ARMAX, noise=0.5)
    truth = np.concatenate([A2[1:], B2[1:], C_ARMAX[1:]])
    both = armax(merge(d1, d2), 2, 2, 1, 1)
    assert both.report.n_samples == 7000
    assert np.all(np.abs(both.theta - truth) < 5 * both.std)
    assert np.all(np.abs(both.std) < armax(d1, 2, 2, 1, 1).std)
    iv = iv4(merge(d1, d2), 2, 2, 1)
    assert np.all(np.abs(iv.theta - truth[:4]) < 5 * iv.std)
    assert oe(merge(d1, d2), 2, 2, 1).report.n_samples == 7000


def test_default_tolerance_stops_within_a_fraction_of_a_standard_deviation():
    # the default tol = 0.1/N stops where further steps change the loss by less than
    # 0.1/N relative: the estimate is statistically the minimizer of a tight tolerance
    data = simulate_siso(20000, 8, C=C_COLORED, noise=2.0)
    default = armax(data, 2, 2, 2, 1)
    tight = armax(data, 2, 2, 2, 1, tol=1e-10)
    assert np.all(np.abs(default.theta - tight.theta) < 0.5 * tight.std)
    assert default.report.iterations <= tight.report.iterations
    truth = np.concatenate([A2[1:], B2[1:], C_COLORED[1:]])
    assert np.all(np.abs(default.theta - truth) < 5 * default.std)


def test_iteration_cap_is_reported_and_progress_called():
    data = simulate_siso(4000, 3, C=C_ARMAX, noise=0.5)
    steps = []
    capped = armax(data, 2, 2, 1, 1, max_iter=1, tol=0.0, progress=lambda k, v: steps.append(k))
    assert steps == [1]
    assert not capped.report.converged and capped.report.max_iter == 1
    assert 'Stopped at the iteration cap (1)' in str(capped)
    free = armax(data, 2, 2, 1, 1)
    assert free.report.converged and free.report.iterations < 50
    assert 'iteration cap' not in str(free)
