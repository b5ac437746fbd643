import numpy as np
import pytest

from maglev_ros.sysid import IdData, OrderError, arx, least_squares, merge
from maglev_ros.sysid.regression import arx_regressors

from .systems import (
    A2,
    B2,
    C_COLORED,
    mean_error,
    mimo_arx_truth,
    simulate_mimo_arx,
    simulate_siso,
)

TRUTH = np.concatenate([A2[1:], B2[1:]])


def test_siso_arx_converges_like_one_over_sqrt_n():
    errors = mean_error(
        lambda N, s: arx(simulate_siso(N, s), 2, 2, 1).theta, [1000, 16000], [0, 1, 2], TRUTH
    )
    ratio = errors[1] / errors[0]
    assert 0.12 < ratio < 0.5  # sqrt(1000/16000) = 0.25


def test_siso_arx_error_within_reported_std():
    model = arx(simulate_siso(20000, 3), 2, 2, 1)
    z = (model.theta - TRUTH) / model.std
    assert np.all(np.abs(z) < 4.5)
    assert model.report.n_samples == 20000
    assert model.noise_variance[0, 0] == pytest.approx(0.04, rel=0.05)


def test_mimo_arx_lab_structure_converges():
    na, nb, nk = [[4, 4], [0, 4]], [[2, 2], [0, 2]], [[1, 1], [1, 1]]
    truth = mimo_arx_truth()
    errors = mean_error(
        lambda N, s: arx(simulate_mimo_arx(N, s), na, nb, nk).theta, [1500, 24000], [0, 1], truth
    )
    assert errors[1] < 0.5 * errors[0]
    model = arx(simulate_mimo_arx(24000, 5), na, nb, nk)
    assert model.orders.n_params == truth.size
    assert np.all(np.abs(model.theta - truth) < 5 * model.std)


def test_normal_equations_and_qr_agree():
    data = simulate_siso(3000, 4)
    a = arx(data, 3, 3, 1, method='normal')
    b = arx(data, 3, 3, 1, method='qr')
    assert np.allclose(a.theta, b.theta, rtol=1e-8, atol=1e-10)
    assert np.allclose(a.covariance, b.covariance, rtol=1e-6)
    assert 'Cholesky' in a.report.method and 'QR' in b.report.method


def test_least_squares_falls_back_to_qr_when_ill_conditioned():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(500)
    Phi = np.column_stack([x, x + 1e-7 * rng.standard_normal(500)])
    theta, _, used = least_squares(Phi, Phi @ np.array([1.0, 2.0]))
    assert used == 'QR'
    assert np.allclose(theta, [1.0, 2.0], atol=1e-5)
    with pytest.raises(ValueError, match="method must be 'auto'"):
        least_squares(Phi, x, method='svd')


def test_regressor_layout_matches_definition():
    data = simulate_siso(50, 0)
    from maglev_ros.sysid import make_orders

    orders = make_orders(1, 1, na=2, nb=2, nk=3)
    Phi = arx_regressors(data.y, data.u, orders, 0, 4)
    t = 10
    row = Phi[t - 4]
    assert np.allclose(
        row, [-data.y[t - 1, 0], -data.y[t - 2, 0], data.u[t - 3, 0], data.u[t - 4, 0]]
    )


def test_colored_noise_biases_arx():
    model = arx(simulate_siso(20000, 7, C=C_COLORED, noise=0.5), 2, 2, 1)
    z = np.abs(model.theta - TRUTH) / model.std
    assert z.max() > 10


def test_multi_experiment_arx_stacks_regressions():
    d1, d2 = simulate_siso(3000, 1), simulate_siso(2000, 2)
    merged = arx(merge(d1, d2), 2, 2, 1)
    Phi = np.vstack([arx_regressors(d.y, d.u, merged.orders, 0, 2) for d in (d1, d2)])
    Y = np.concatenate([d.y[2:, 0] for d in (d1, d2)])
    assert np.allclose(merged.theta, np.linalg.lstsq(Phi, Y, rcond=None)[0])


def test_arx_errors():
    data = simulate_siso(30, 0)
    with pytest.raises(ValueError, match='fewer samples than parameters'):
        arx(data, 10, 10, 1)
    with pytest.raises(OrderError, match='na must be a scalar or have shape'):
        arx(simulate_mimo_arx(100, 0), [[1, 1, 1]], 1, 1)
    with pytest.raises(OrderError, match='nk must be >= 0'):
        arx(data, 1, 1, -1)
    with pytest.raises(TypeError, match='data must be IdData'):
        arx(np.zeros((10, 2)), 1, 1)


def test_arx_nk_zero_uses_direct_feedthrough():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(2000)
    y = 0.7 * u + np.concatenate([[0], 0.5 * u[:-1]]) + 0.01 * rng.standard_normal(2000)
    model = arx(IdData(y, u, 1.0), 0, 2, 0)
    assert np.allclose(model.theta, [0.7, 0.5], atol=0.01)


def test_correlation_normal_equations_match_qr_siso_and_mimo():
    data = simulate_siso(5000, 8)
    auto = arx(data, 7, 9, 1)
    assert 'correlations' in auto.report.method
    assert np.allclose(auto.theta, arx(data, 7, 9, 1, method='qr').theta, rtol=1e-6, atol=1e-8)
    mimo = simulate_mimo_arx(3000, 4)
    orders = ([[4, 4], [0, 4]], [[2, 2], [0, 2]], [[1, 2], [1, 1]])
    a, q = arx(mimo, *orders), arx(mimo, *orders, method='qr')
    assert np.allclose(a.theta, q.theta, rtol=1e-7, atol=1e-9)
    assert np.allclose(a.covariance, q.covariance, rtol=1e-5, atol=1e-12)


def test_noise_free_data_is_solved_exactly():
    data = simulate_siso(2000, 1, noise=0.0)
    model = arx(data, 2, 2, 1)
    assert np.allclose(model.theta, TRUTH, atol=1e-9)


def test_ill_conditioned_correlation_path_is_refined_to_qr_accuracy():
    from scipy.signal import lfilter

    rng = np.random.default_rng(5)
    u = lfilter([1.0], [1, -0.8], rng.standard_normal(20000))  # smooth input
    A = np.real(np.poly([0.95, 0.9, 0.8, 0.6 + 0.3j, 0.6 - 0.3j, 0.3, -0.2]))
    y = lfilter(np.r_[0, np.ones(9) / 9], A, u) + 1e-3 * rng.standard_normal(20000)
    data = IdData(y, u, 1.0)
    from maglev_ros.sysid import make_orders
    from maglev_ros.sysid.arx import row_blocks, signal_matrix
    from maglev_ros.sysid.correlation import lag_gram

    blocks = row_blocks(make_orders(1, 1, na=7, nb=9, nk=1), 0)
    R = lag_gram(signal_matrix(data), blocks, blocks, 9)
    assert np.linalg.cond(R) > 1e10  # the refinement branch is exercised
    auto, qr = arx(data, 7, 9, 1), arx(data, 7, 9, 1, method='qr')
    assert 'correlations' in auto.report.method
    assert np.max(np.abs(auto.theta - qr.theta)) < 1e-6 * np.max(np.abs(qr.theta))
