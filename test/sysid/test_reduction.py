"""Balanced truncation: error bound, Hankel singular values, unstable part, the lab's model."""

import numpy as np
import pytest
from scipy import linalg

from maglev_ros.sysid import arx
from maglev_ros.sysid.reduction import (
    StateSpaceModel,
    balanced_truncation,
    hankel_singular_values,
)
from maglev_ros.sysid.reduction_plots import reduction_plot

from .physics_runs import lab_x

F = np.linspace(0.0, 0.5, 400)  # Hz with Ts = 1


def stable_system(seed=0, n=8):
    rng = np.random.default_rng(seed)
    poles = np.r_[0.95, 0.9, 0.7, 0.5, -0.3, 0.2, 0.1, 0.05][:n]
    V = rng.standard_normal((n, n))
    A = V @ np.diag(poles) @ np.linalg.inv(V)
    B = rng.standard_normal((n, 1)) * np.logspace(0, -3, n)[:, None]
    B = V @ (np.linalg.inv(V) @ B)
    return StateSpaceModel(A, B, rng.standard_normal((1, n)), np.zeros((1, 1)), 1.0)


def test_error_within_the_bound_and_hsv_match_the_gramians():
    full = stable_system()
    hsv, n_unstable = hankel_singular_values(full)
    P = linalg.solve_discrete_lyapunov(full.A, full.B @ full.B.T)
    Q = linalg.solve_discrete_lyapunov(full.A.T, full.C.T @ full.C)
    direct = np.sort(np.sqrt(np.abs(np.linalg.eigvals(P @ Q))))[::-1]
    np.testing.assert_allclose(
        hsv, direct, rtol=1e-6, atol=1e-7 * hsv[0]
    )  # eig(PQ) is the less accurate one
    assert n_unstable == 0
    for order in (2, 4, 6):
        red = balanced_truncation(full, order=order)
        error = np.abs(full.freqresp(F) - red.reduced.freqresp(F)).max()
        assert red.order == order
        assert error <= red.error_bound * (1 + 1e-6)
        assert error >= hsv[order] * 0.999  # the lower bound: no better than the next sigma
        assert np.all(np.abs(red.reduced.poles()) < 1)


def test_unstable_part_is_kept_whole():
    stable = stable_system(seed=1, n=6)
    A = linalg.block_diag(stable.A, [[1.25]])
    B = np.vstack([stable.B, [[1.0]]])
    C = np.hstack([stable.C, [[0.5]]])
    full = StateSpaceModel(A, B, C, np.zeros((1, 1)), 1.0)
    red = balanced_truncation(full, order=3)
    assert red.n_unstable == 1 and red.kept == 2
    assert np.min(np.abs(red.reduced.poles() - 1.25)) < 1e-10
    u = np.random.default_rng(0).standard_normal((40, 1))
    np.testing.assert_allclose(red.reduced.simulate(u), full.simulate(u), atol=0.2 * 1.25**40)
    with pytest.raises(ValueError, match='order must be from 1 .the unstable states'):
        balanced_truncation(full, order=0)


def test_lab_arx_7_9_1_reduced_by_the_default_rule(tmp_path, capsys):
    est, val = lab_x().split(0.5)
    model = arx(est, 7, 9, 1)
    red = balanced_truncation(model)
    full_fit, reduced_fit = red.fit_loss(val)
    with capsys.disabled():
        print(f'\n{red.summary()}')
        print(
            f'validation simulation fit: full {full_fit[0]:.3f} %, reduced {reduced_fit[0]:.3f} %'
        )
    assert red.order < red.full.order
    assert full_fit[0] - reduced_fit[0] < 1.0
    assert reduction_plot(red, tmp_path / 'hsv.png').stat().st_size > 0
