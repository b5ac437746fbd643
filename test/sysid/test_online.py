"""OnlineArx: the identifier's recursive ARX against RecursiveArx, batch ARX and known systems."""

import numpy as np
import pytest
from scipy.signal import lfilter

from maglev_ros.sysid import IdData, RecursiveArx, arx, rls_arx
from maglev_ros.sysid.online import OnlineArx, coefficient_layout

from .systems import A2, B2, mimo_arx_truth, simulate_mimo_arx, simulate_siso

LAB_NA, LAB_NB = [[4, 4], [0, 4]], [[2, 2], [0, 2]]


def feed(estimator, data, stop=None):
    errors = [
        estimator.update(data.y[t], data.u[t]) for t in range(data.N if stop is None else stop)
    ]
    return np.array(errors)


def test_same_numbers_as_recursive_arx_and_rls_arx():
    data = simulate_mimo_arx(4000, 1)
    reference = RecursiveArx(LAB_NA, LAB_NB, 1, 2, 2, forgetting=0.99, p0=1e3)
    online = OnlineArx(LAB_NA, LAB_NB, 1, 2, 2, 0.99, 1e3, wait_for_history=False)
    for t in range(data.N):
        reference.update(data.y[t], data.u[t])
        online.update(data.y[t], data.u[t])
        if t in (0, 5, 1000):
            assert np.array_equal(online.theta, reference.theta)
    assert np.array_equal(online.theta, reference.theta)
    assert np.array_equal(online.theta, rls_arx(data, LAB_NA, LAB_NB, 1, 0.99, 1e3).theta[-1])


def test_recursive_arx_is_the_weighted_least_squares_with_forgetting():
    """Regression: an asymmetric covariance update drifted 50 % off within 3000 samples."""
    data = simulate_siso(5000, 2)
    lam, p0 = 0.99, 1e4
    reference = RecursiveArx(2, 2, 1, forgetting=lam, p0=p0)
    feed(reference, data)
    y, u = np.r_[0.0, 0.0, data.y[:, 0]], np.r_[0.0, 0.0, data.u[:, 0]]
    Phi = np.column_stack([-y[1:-1], -y[:-2], u[1:-1], u[:-2]])
    w = lam ** np.arange(data.N - 1, -1, -1)
    R = Phi.T @ (w[:, None] * Phi) + lam**data.N / p0 * np.eye(4)
    exact = np.linalg.solve(R, Phi.T @ (w * data.y[:, 0]))
    np.testing.assert_allclose(reference.theta, exact, rtol=1e-8)


@pytest.mark.parametrize(
    ('data', 'na', 'nb', 'nk'),
    [
        (simulate_siso(20000, 2), 2, 2, 1),
        (simulate_siso(20000, 3, noise=0.5), 7, 9, 3),
        (simulate_mimo_arx(20000, 1), LAB_NA, LAB_NB, 1),
    ],
    ids=['siso-2-2-1', 'siso-7-9-3', 'mimo-lab'],
)
def test_forgetting_one_converges_to_batch_arx(data, na, nb, nk):
    online = OnlineArx(na, nb, nk, data.ny, data.nu)  # forgetting 1, P0 = 1e4 I: the defaults
    feed(online, data)
    batch = arx(data, na, nb, nk).theta
    assert np.max(np.abs(online.theta - batch)) < 1e-6 * np.max(np.abs(batch))
    assert online.status().samples == data.N


def test_sliding_window_is_the_least_squares_of_the_last_samples():
    data = simulate_siso(6000, 4)
    W = 1500
    online = OnlineArx(2, 2, 1, window=W, initial_covariance=1e8)
    feed(online, data)
    last = arx(data[data.N - W - 2 :], 2, 2, 1).theta  # regressors of the last W samples
    np.testing.assert_allclose(online.theta, last, rtol=1e-6)


def step_system(N, seed):
    """ARX data whose B gain rises 60 % and a pole moves at N/2 (a new operating point)."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(N)
    e = 0.05 * rng.standard_normal(N)
    half = N // 2
    A_new, B_new = np.array([1.0, -1.3, 0.6]), 1.6 * B2
    y1 = lfilter(B2, A2, u[:half]) + lfilter([1.0], A2, e[:half])
    # continue with the new polynomials from the old state (difference equation)
    y = np.concatenate([y1, np.zeros(N - half)])
    for t in range(half, N):
        y[t] = (
            -A_new[1] * y[t - 1] - A_new[2] * y[t - 2] + B_new[1] * u[t - 1] + B_new[2] * u[t - 2]
        ) + e[t]
    after = np.concatenate([A_new[1:], B_new[1:]])
    before = np.concatenate([A2[1:], B2[1:]])
    return IdData(y, u, 2e-4), before, after


def test_forgetting_follows_a_change_of_operating_point():
    data, before, after = step_system(16000, 5)
    tracking, frozen = OnlineArx(2, 2, 1, forgetting=0.999), OnlineArx(2, 2, 1)
    half = data.N // 2
    for t in range(data.N):
        tracking.update(data.y[t], data.u[t])
        frozen.update(data.y[t], data.u[t])
        if t == half - 1:
            np.testing.assert_allclose(tracking.theta, before, atol=0.02)
    error = np.linalg.norm(tracking.theta - after) / np.linalg.norm(after)
    stuck = np.linalg.norm(frozen.theta - after) / np.linalg.norm(after)
    assert error < 0.01 and stuck > 0.1, (error, stuck)


def test_prediction_error_fit_and_diagnostics():
    data = simulate_siso(3000, 6, noise=0.0)  # noise-free ARX data: predictions become exact
    online = OnlineArx(2, 2, 1, fit_window=500)
    errors = feed(online, data)
    assert np.all(np.isnan(errors[:2])) and np.all(np.isfinite(errors[2:]))  # history first
    assert np.abs(errors[-500:]).max() < 1e-6
    first = online.status()
    assert first.fit[0] > 99.999 and first.drift == 0.0
    assert first.covariance_trace < 1e-2  # from 4e4 at the start
    online.update(data.y[0], data.u[0])  # an odd sample moves the estimate a little
    second = online.status()
    assert 0 < second.drift and second.relative_drift == pytest.approx(
        second.drift / np.linalg.norm(second.theta)
    )
    noisy = simulate_siso(6000, 7, noise=0.2)
    online = OnlineArx(2, 2, 1, fit_window=2000)
    feed(online, noisy)
    expected = 100 * (1 - 0.2 / np.std(noisy.y[-2000:]))  # white equation noise of 0.2
    assert online.fit()[0] == pytest.approx(expected, abs=1.0)


def test_reset_starts_over():
    data = simulate_siso(800, 8)
    online = OnlineArx(2, 2, 1, window=300)
    fresh = OnlineArx(2, 2, 1, window=300)
    feed(online, data)
    online.reset()
    assert online.samples == 0 and not np.any(online.theta)
    assert online.status().covariance_trace == pytest.approx(4e4)
    feed(online, data, 500)
    feed(fresh, data, 500)
    assert np.array_equal(online.theta, fresh.theta)


def test_coefficient_layout_labels_the_polynomials():
    orders = OnlineArx(LAB_NA, LAB_NB, 1, 2, 2).orders
    truth = mimo_arx_truth()
    layout = coefficient_layout(orders, truth, ['Bx', 'By'], ['ux', 'uy'])
    assert layout.labels == (
        'theta',
        'A[Bx,Bx] na=4',
        'A[Bx,By] na=4',
        'B[Bx,ux] nb=2 nk=1',
        'B[Bx,uy] nb=2 nk=1',
        'A[By,By] na=4',
        'B[By,uy] nb=2 nk=1',
    )
    assert layout.dims[0] == ('theta', 18, 18)
    assert [d[1] for d in layout.dims[1:]] == [4, 4, 2, 2, 4, 2]
    assert [d[2] for d in layout.dims[1:]] == [0, 4, 8, 10, 12, 16]  # offsets
    np.testing.assert_array_equal(layout.data, truth)
    np.testing.assert_array_equal(layout.block('B[By,uy]'), truth[16:])
    siso = coefficient_layout(OnlineArx(7, 9, 1).orders, np.arange(16.0))
    assert siso.labels == ('theta', 'A[y1,y1] na=7', 'B[y1,u1] nb=9 nk=1')
    with pytest.raises(ValueError, match='theta must have 16 values'):
        coefficient_layout(OnlineArx(7, 9, 1).orders, np.zeros(3))


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'forgetting': 0.0}, r'forgetting factor must be in \(0, 1\]'),
        ({'forgetting': 1.1}, r'forgetting factor must be in \(0, 1\]'),
        ({'initial_covariance': -1.0}, 'initial covariance must be > 0'),
        ({'window': 0}, 'window must be a sample count'),
        ({'fit_window': 1}, 'fit_window must be a sample count >= 2'),
    ],
)
def test_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        OnlineArx(2, 2, 1, **kwargs)


def test_bad_samples_leave_the_state_unchanged():
    online = OnlineArx(2, 2, 1)
    online.update([1.0], [0.5])
    with pytest.raises(ValueError, match='finite'):
        online.update([np.nan], [0.5])
    with pytest.raises(ValueError, match=r'y of shape \(1,\)'):
        online.update([1.0, 2.0], [0.5])
    assert online.samples == 1
