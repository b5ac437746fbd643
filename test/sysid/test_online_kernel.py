"""OnlineArx's compiled update and update_many: bit for bit the per-sample numpy code."""

from collections import deque

import numpy as np
import pytest
from scipy.linalg import block_diag
from scipy.signal import lfilter

from maglev_ros.sysid.online import OnlineArx
from maglev_ros.sysid.orders import make_orders
from maglev_ros.sysid.rls import rls_step

N = 20_000


class LegacyOnlineArx:
    """Copy of ``OnlineArx`` before the compiled kernel: per-sample numpy (window included)."""

    def __init__(
        self,
        na,
        nb,
        nk=1,
        ny=1,
        nu=1,
        forgetting=1.0,
        initial_covariance=1e4,
        window=None,
        fit_window=1000,
        wait_for_history=True,
    ):
        self.orders = make_orders(ny, nu, na=na, nb=nb, nk=nk)
        self.forgetting = float(forgetting)
        self.initial_covariance = float(initial_covariance)
        self.window = None if window is None else int(window)
        self.fit_window = int(fit_window)
        self.wait_for_history = bool(wait_for_history)
        o = self.orders
        self._ylags = max(1, int(o.na.max(initial=0)))
        self._ulags = max(1, int((o.nk + o.nb).max(initial=1)))
        self._index = []
        for i in range(o.ny):
            idx = []
            for j in range(o.ny):
                idx += [j * self._ylags + lag - 1 for lag in range(1, o.na[i, j] + 1)]
            base = o.ny * self._ylags
            for j in range(o.nu):
                k = int(o.nk[i, j])
                idx += [base + j * self._ulags + lag for lag in range(k, k + o.nb[i, j])]
            self._index.append(np.array(idx, dtype=np.intp))
        self._starts = [o.row_start(i) for i in range(o.ny)]
        self._sizes = o.row_sizes()
        self.reset()

    def reset(self):
        o = self.orders
        self._yh = np.zeros((o.ny, self._ylags))
        self._uh = np.zeros((o.nu, self._ulags))
        self._theta = [np.zeros(s) for s in self._sizes]
        self._P = [self.initial_covariance * np.eye(s) for s in self._sizes]
        self.samples = 0
        self._updates = np.zeros(o.ny, dtype=np.int64)
        self._last_error = np.full(o.ny, np.nan)
        self._fit_y = np.full((self.fit_window, o.ny), np.nan)
        self._fit_e = np.full((self.fit_window, o.ny), np.nan)
        self._window = [deque() for _ in range(o.ny)]

    @property
    def theta(self):
        return np.concatenate(self._theta)

    @property
    def covariance(self):
        return block_diag(*self._P)

    def update(self, y, u):
        o = self.orders
        y = np.atleast_1d(np.asarray(y, dtype=float))
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if y.shape != (o.ny,) or u.shape != (o.nu,):
            raise ValueError(
                f'update needs y of shape ({o.ny},) and u of shape ({o.nu},), '
                f'got {y.shape} and {u.shape}'
            )
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
            raise ValueError(f'samples must be finite, got y={y.tolist()} u={u.tolist()}')
        self._uh[:, 1:] = self._uh[:, :-1]
        self._uh[:, 0] = u
        flat = np.concatenate([-self._yh.ravel(), self._uh.ravel()])
        errors = np.full(o.ny, np.nan)
        for i in range(o.ny):
            if self.wait_for_history and self.samples < self._starts[i]:
                continue
            phi = flat[self._index[i]]
            errors[i] = rls_step(self._P[i], self._theta[i], phi, float(y[i]), self.forgetting)
            self._updates[i] += 1
            if self.window is not None:
                self._slide(i, phi, float(y[i]))
        self._yh[:, 1:] = self._yh[:, :-1]
        self._yh[:, 0] = y
        slot = self.samples % self.fit_window
        self._fit_y[slot] = y
        self._fit_e[slot] = errors
        self._last_error = errors
        self.samples += 1
        return errors

    def _slide(self, i, phi, y):
        kept = self._window[i]
        kept.append((phi, y))
        if len(kept) <= self.window:
            return
        old_phi, old_y = kept.popleft()
        weight = self.forgetting**self.window
        P, theta = self._P[i], self._theta[i]
        Pphi = P @ old_phi
        denom = 1.0 / weight - old_phi @ Pphi
        theta -= Pphi / denom * (old_y - old_phi @ theta)
        P += np.outer(Pphi, Pphi) / denom


CONFIGS = {
    'siso-2-2-1': dict(na=2, nb=2, nk=1),
    'siso-7-9-3-lambda-nowait': dict(na=7, nb=9, nk=3, forgetting=0.999, wait_for_history=False),
    'miso-nk0': dict(na=[[3]], nb=[[2, 4]], nk=[[0, 2]], ny=1, nu=2, forgetting=0.999),
    'mimo-node-p0-1e10': dict(
        na=[[7, 0], [0, 6]],
        nb=[[9, 0], [0, 6]],
        nk=[[1, 1], [1, 1]],
        ny=2,
        nu=2,
        initial_covariance=1e10,
    ),
    'mimo-lab-lambda-nowait': dict(
        na=[[4, 4], [0, 4]],
        nb=[[2, 2], [0, 2]],
        nk=1,
        ny=2,
        nu=2,
        forgetting=0.999,
        initial_covariance=1e3,
        wait_for_history=False,
    ),
    'siso-window': dict(na=2, nb=2, nk=1, window=300, forgetting=0.999, fit_window=50),
    'mimo-window': dict(
        na=[[2, 1], [0, 2]], nb=[[2, 1], [0, 2]], nk=[[1, 0], [1, 1]], ny=2, nu=2, window=500
    ),
}


def signals(kwargs, n=N, seed=0):
    """Random inputs (n, nu) and ARX-like outputs (n, ny) plus noise."""
    ny, nu = kwargs.get('ny', 1), kwargs.get('nu', 1)
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((n, nu))
    Y = np.empty((n, ny))
    for i in range(ny):
        drive = U @ rng.uniform(-1, 1, nu)
        Y[:, i] = lfilter([0.0, 0.5, 0.3], [1.0, -1.2, 0.5], drive)
    Y += 0.1 * rng.standard_normal((n, ny))
    return Y, U


def state(arx):
    """Everything update changes, as arrays (for exact comparison)."""
    return dict(
        theta=arx.theta,
        P=arx.covariance,
        samples=np.array(arx.samples),
        updates=arx._updates.copy(),
        last_error=np.array(arx._last_error),
        fit_y=arx._fit_y.copy(),
        fit_e=arx._fit_e.copy(),
        yh=arx._yh.copy(),
        uh=arx._uh.copy(),
    )


def assert_same_state(a, b):
    sa, sb = state(a), state(b)
    for key, value in sa.items():
        np.testing.assert_array_equal(sb[key], value, err_msg=key)


@pytest.mark.parametrize('kwargs', CONFIGS.values(), ids=CONFIGS.keys())
def test_update_is_bit_for_bit_the_numpy_code(kwargs):
    Y, U = signals(kwargs)
    legacy, online = LegacyOnlineArx(**kwargs), OnlineArx(**kwargs)
    for t in range(N):
        np.testing.assert_array_equal(online.update(Y[t], U[t]), legacy.update(Y[t], U[t]))
        if t in (0, 3, 10, 1000):
            assert_same_state(legacy, online)
    assert_same_state(legacy, online)
    np.testing.assert_array_equal(online.fit(), _fit(legacy))
    assert online.status().covariance_trace == sum(np.trace(P) for P in legacy._P)


def _fit(legacy):
    """OnlineArx.fit of the legacy buffers (the method is unchanged)."""
    probe = OnlineArx.__new__(OnlineArx)
    probe.orders, probe._fit_y, probe._fit_e = legacy.orders, legacy._fit_y, legacy._fit_e
    return OnlineArx.fit(probe)


@pytest.mark.parametrize('kwargs', CONFIGS.values(), ids=CONFIGS.keys())
def test_update_many_is_update_row_by_row(kwargs):
    Y, U = signals(kwargs, seed=1)
    legacy, online = LegacyOnlineArx(**kwargs), OnlineArx(**kwargs)
    rng = np.random.default_rng(2)
    t = 0
    while t < N:
        n = int(rng.integers(0, 8))  # bursts of 0 .. 7 samples, some single updates between
        if n == 7:
            np.testing.assert_array_equal(online.update(Y[t], U[t]), legacy.update(Y[t], U[t]))
            t += 1
            continue
        got = online.update_many(Y[t : t + n], U[t : t + n])
        expected = [legacy.update(Y[k], U[k]) for k in range(t, min(t + n, N))]
        assert got.shape == (len(expected), online.orders.ny)
        np.testing.assert_array_equal(got, np.reshape(expected, got.shape))
        t += n
        if t < 40 or t % 997 < 7:
            assert_same_state(legacy, online)
    assert_same_state(legacy, online)


def test_update_many_whole_record_and_reset():
    kwargs = CONFIGS['mimo-node-p0-1e10']
    Y, U = signals(kwargs, n=3000, seed=3)
    legacy, online = LegacyOnlineArx(**kwargs), OnlineArx(**kwargs)
    expected = np.array([legacy.update(Y[t], U[t]) for t in range(3000)])
    np.testing.assert_array_equal(online.update_many(Y.tolist(), U.tolist()), expected)
    assert_same_state(legacy, online)
    online.reset()
    legacy.reset()
    assert_same_state(legacy, online)
    assert online.status().covariance_trace == pytest.approx(28 * 1e10)
    np.testing.assert_array_equal(online.update_many(Y[:500], U[:500]), expected[:500])
    for t in range(500):
        legacy.update(Y[t], U[t])
    assert_same_state(legacy, online)


def test_inputs_as_lists_scalars_and_strided_views():
    siso, legacy = OnlineArx(2, 2, 1), LegacyOnlineArx(2, 2, 1)
    for t, (y, u) in enumerate([(1.0, 0.5), ([2.0], [0.25]), (np.float32(0.5), np.array(3))]):
        np.testing.assert_array_equal(siso.update(y, u), legacy.update(y, u), err_msg=str(t))
    kwargs = CONFIGS['mimo-lab-lambda-nowait']
    Y, U = signals(kwargs, n=200, seed=4)
    online, legacy = OnlineArx(**kwargs), LegacyOnlineArx(**kwargs)
    YF, UF = np.asfortranarray(Y), np.asfortranarray(U)
    for t in range(100):  # rows of Fortran arrays: strided (ny,) views
        np.testing.assert_array_equal(online.update(YF[t], UF[t]), legacy.update(Y[t], U[t]))
    np.testing.assert_array_equal(
        online.update_many(YF[100:], UF[100:]),
        [legacy.update(Y[t], U[t]) for t in range(100, 200)],
    )
    assert_same_state(legacy, online)


@pytest.mark.parametrize('window', [None, 50], ids=['kernel', 'window'])
def test_bad_samples_leave_the_state_unchanged(window):
    kwargs = dict(CONFIGS['mimo-node-p0-1e10'], window=window)
    Y, U = signals(kwargs, n=60, seed=5)
    online, reference = OnlineArx(**kwargs), OnlineArx(**kwargs)
    online.update_many(Y[:30], U[:30])
    reference.update_many(Y[:30], U[:30])
    bad_y = Y[30:35].copy()
    bad_y[3, 1] = np.nan
    bad_u = U[30:35].copy()
    bad_u[1, 0] = np.inf
    cases = [
        (lambda: online.update([np.nan, 1.0], [0.0, 0.0]), 'samples must be finite'),
        (lambda: online.update([1.0, 1.0], [-np.inf, 0.0]), 'samples must be finite'),
        (lambda: online.update([1.0], [0.0, 0.0]), r'y of shape \(2,\)'),
        (lambda: online.update([1.0, 2.0], [0.0, 0.0, 1.0]), r'u of shape \(2,\)'),
        (lambda: online.update(np.ones((2, 1)), [0.0, 0.0]), r'got \(2, 1\)'),
        (lambda: online.update_many(bad_y, U[30:35]), r'finite.*\(row 3\)'),
        (lambda: online.update_many(Y[30:35], bad_u), r'finite.*\(row 1\)'),
        (lambda: online.update_many(Y[30:35], U[30:34]), r'U of shape \(n, 2\)'),
        (lambda: online.update_many(Y[30:35, :1], U[30:35]), r'Y of shape \(n, 2\)'),
        (lambda: online.update_many(Y[30], U[30]), r'Y of shape \(n, 2\)'),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()
        assert_same_state(reference, online)
    np.testing.assert_array_equal(
        online.update_many(Y[30:], U[30:]), reference.update_many(Y[30:], U[30:])
    )
    assert_same_state(reference, online)


def test_empty_burst_changes_nothing():
    online = OnlineArx(2, 2, 1)
    online.update(1.0, 0.5)
    before = state(online)
    errors = online.update_many(np.zeros((0, 1)), np.zeros((0, 1)))
    assert errors.shape == (0, 1)
    for key, value in before.items():
        np.testing.assert_array_equal(state(online)[key], value, err_msg=key)


def test_theta_is_a_copy_and_rows_are_views():
    online = OnlineArx([[2, 1], [0, 3]], [[1, 2], [2, 0]], 1, 2, 2)
    theta = online.theta
    theta[:] = 7.0
    assert not np.any(online.theta)
    online.update([1.0, 2.0], [0.5, -0.5])
    online.update_many(np.ones((5, 2)), np.ones((5, 2)))
    np.testing.assert_array_equal(online.theta, np.concatenate(online._theta))
    assert [P.shape for P in online._P] == [(6, 6), (5, 5)]
    assert all(P.flags.c_contiguous for P in online._P)
