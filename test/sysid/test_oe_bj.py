import numpy as np
import pytest

from maglev_ros.sysid import OrderError, arx, bj, oe

from .systems import B2, C_BJ, D_BJ, F_OE, mean_error, simulate_mimo_arx, simulate_siso

ONE = np.array([1.0])


def oe_data(N, seed):
    return simulate_siso(N, seed, A=ONE, F=F_OE, noise=0.5)


def bj_data(N, seed):
    return simulate_siso(N, seed, A=ONE, F=F_OE, C=C_BJ, D=D_BJ, noise=0.5)


def test_oe_converges_like_one_over_sqrt_n():
    truth = np.concatenate([B2[1:], F_OE[1:]])
    errors = mean_error(
        lambda N, s: oe(oe_data(N, s), 2, 2, 1).theta, [1000, 16000], [0, 1, 2], truth
    )
    assert 0.1 < errors[1] / errors[0] < 0.5
    model = oe(oe_data(16000, 4), 2, 2, 1)
    assert np.all(np.abs(model.theta - truth) < 5 * model.std)
    assert model.structure == 'oe' and model.is_stable


def test_bj_converges_and_recovers_noise_model():
    truth = np.concatenate([B2[1:], C_BJ[1:], D_BJ[1:], F_OE[1:]])
    errors = mean_error(
        lambda N, s: bj(bj_data(N, s), 2, 1, 1, 2, 1).theta, [1500, 24000], [0, 1], truth
    )
    assert errors[1] < 0.45 * errors[0]
    model = bj(bj_data(24000, 8), 2, 1, 1, 2, 1)
    assert np.all(np.abs(model.theta - truth) < 5 * model.std)


def test_oe_is_unbiased_where_arx_is_not():
    data = oe_data(20000, 2)
    model = oe(data, 2, 2, 1)
    ref = arx(data, 2, 2, 1)
    truth_f = F_OE[1:]
    assert np.linalg.norm(model.polynomial('F')[1:] - truth_f) < 0.2 * np.linalg.norm(
        ref.polynomial('A')[1:] - truth_f
    )


def test_oe_bj_are_siso_only():
    with pytest.raises(OrderError, match='single-input single-output'):
        oe(simulate_mimo_arx(500, 0), 2, 2, 1)
    with pytest.raises(OrderError, match='nb must be >= 1'):
        oe(oe_data(500, 0), 0, 2, 1)
