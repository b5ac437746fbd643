"""The V4x PC-control firmware's field processing, as a measurement model."""

import numpy as np
import pytest

from maglev_ros.physics import MaggyModel, load_parameters
from maglev_ros.physics.board_processing import BoardProcessing, augment


@pytest.fixture(scope='module')
def model():
    return MaggyModel(load_parameters('maggy_v4'))


def test_baseline_and_feedthrough_are_the_models_own_field(model):
    bp = BoardProcessing.from_model(model)
    x = model.hover_state(0.03)
    n = model.params.solenoids.count
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, n)
    raw = model.measurement(x, u, with_magnet=False)
    processed = raw - bp.baseline - bp.feedthrough @ u
    axes = np.arange(raw.size) % 3
    # magnet absent: nothing is left on x and y; z keeps the coils' field (not compensated)
    np.testing.assert_allclose(processed[axes < 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(processed[axes == 2], (raw - bp.baseline)[axes == 2])
    # the permanent magnets' field (tens of mT) is what the baseline takes away
    assert np.abs(bp.baseline).max() > 0.01
    assert list(bp.filtered) == [True, True, False] * (raw.size // 3)
    selected = BoardProcessing.from_model(model, sensors=[1])
    np.testing.assert_array_equal(selected.baseline, bp.baseline[3:6])


def test_a_measured_pair_feedthrough_is_what_the_processing_then_leaves(model):
    """A board whose own compensation is off: each pair's processed field per ampere is the
    measured one (the pairs are driven antisymmetrically: x+ at +i, x- at -i)."""
    exact = BoardProcessing.model_pairs(model, sensors=[0])
    assert np.allclose(exact[:2], 0.0, atol=1e-12)  # the model's own: nothing left on x, y
    measured = exact + np.array([[2.5e-5, -1e-6], [1e-6, -4.2e-5], [3e-6, 0.0]])
    bp = BoardProcessing.from_model(model, sensors=[0], pairs=measured)
    x = model.hover_state(0.03)
    base = model.measurement(x, np.zeros(4), with_magnet=False)[:3]
    for col, pair in enumerate(([1.0, -1.0, 0.0, 0.0], [0.0, 0.0, 1.0, -1.0])):
        i = 0.7 * np.array(pair)
        raw = model.measurement(x, i, with_magnet=False)[:3]
        processed = raw - bp.baseline - bp.feedthrough @ i
        np.testing.assert_allclose(processed, 0.7 * measured[:, col], atol=1e-12)
    np.testing.assert_allclose(bp.baseline, base)
    with pytest.raises(ValueError, match=r'pairs must be finite, shape \(3, 2\)'):
        BoardProcessing.from_model(model, sensors=[0], pairs=np.zeros((2, 2)))


def test_host_rate_filter_matches_the_board_loop_for_held_signals(model):
    bp = BoardProcessing.from_model(model, sensors=[0])
    Ts = 1e-3  # 5 board steps per host sample
    a = bp.host_pole(Ts)
    assert a == pytest.approx(0.8**5)
    # the board's own loop on a signal held over each host period
    b = np.repeat([0.0, 1.0, 1.0, -2.0, 0.5], 5)
    f, board = 0.0, []
    for v in b:
        f = 0.2 * v + 0.8 * f
        board.append(f)
    raw = np.zeros((5, 3))
    raw[:, 0] = b[::5] + bp.baseline[0]
    host = bp.apply(raw, np.zeros((5, 4)), Ts)
    np.testing.assert_allclose(host[1:, 0], np.array(board)[9::5], rtol=1e-12)


def test_augmented_model_equals_filtering_its_output():
    rng = np.random.default_rng(1)
    ad = np.diag([0.9, 0.5])
    bd = rng.standard_normal((2, 1))
    c = rng.standard_normal((3, 2))
    d = rng.standard_normal((3, 1))
    filtered = np.array([True, True, False])
    a = 0.3
    ad2, bd2, c2, d2 = augment(ad, bd, c, d, filtered, a)
    u = rng.standard_normal((50, 1))
    x = np.zeros(2)
    s = np.zeros(4)
    f = np.zeros(2)
    for k in range(50):
        y = c @ x + d @ u[k]
        f = a * f + (1 - a) * y[:2] if k else (1 - a) * y[:2]
        y2 = c2 @ s + d2 @ u[k]
        np.testing.assert_allclose(y2, np.r_[f, y[2]], atol=1e-12)
        x = ad @ x + bd @ u[k]
        s = ad2 @ s + bd2 @ u[k]


def test_host_filter_is_the_board_loop_on_the_continuous_model(model):
    """The filter states over a 1 ms host sample equal the 5 kHz loop run on the plant."""
    from scipy.linalg import expm

    from maglev_ros.physics import linearize
    from maglev_ros.physics.board_processing import augment_exact

    bp = BoardProcessing.from_model(model, sensors=[0])
    lin = linearize(model).reduced()
    rows = [0, 1, 2]
    A, B = lin.A, lin.B
    c = lin.C[rows]
    d = lin.D[rows] - bp.feedthrough
    Ts, steps = 1e-3, 5
    n, m = A.shape[0], B.shape[1]
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = A, B
    e = expm(big * 2e-4)
    phi, gam = e[:n, :n], e[:n, n:]
    ad, bd, c2, d2 = augment_exact(A, B, c, d, bp, bp.filtered, Ts)
    rng = np.random.default_rng(3)
    x = rng.normal(0, 1e-4, n)
    f = rng.normal(0, 1e-4, 2)
    state = np.concatenate([x, f])
    for _ in range(20):
        u = rng.uniform(-1, 1, m)
        for _ in range(steps):  # the board: its plant and its filter every 200 us
            x = phi @ x + gam @ u
            f = 0.8 * f + 0.2 * (c[:2] @ x + d[:2] @ u)
        state = ad @ state + bd @ u
        np.testing.assert_allclose(state[:n], x, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose((c2 @ state + d2 @ u)[:2], f, rtol=1e-9, atol=1e-15)
        z = c[2] @ x + d[2] @ u  # z is read unfiltered
        assert (c2 @ state + d2 @ u)[2] == pytest.approx(z, rel=1e-9, abs=1e-15)
    # the filter state decays with the pole of the host-rate shortcut
    a = bp.host_pole(Ts)
    assert ad[n, n] == pytest.approx(a)


@pytest.mark.parametrize('Ts', [2e-4, 1e-3, 1.25e-3])
def test_sensor_noise_is_read_back_from_the_filtered_readings(Ts):
    """White sensor noise filtered at every board step, read at the host rate: the noise
    level that second differences give (as for white readings) leads back to it."""
    from scipy.signal import lfilter

    from maglev_ros.greybox import noise_level

    board = BoardProcessing(np.zeros(3), np.zeros((3, 4)), np.array([True, True, False]))
    steps = board.board_steps(Ts)
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 1e-4, (200_000 * steps, 2))  # T, per board step
    filtered = lfilter([board.weight], [1.0, board.weight - 1.0], noise, axis=0)
    readings = filtered[steps - 1 :: steps]  # the host reads after each M-th board step
    level = noise_level(readings)
    assert level.max() < 0.6e-4  # the filter hides most of it from a white-noise reading
    assert board.sensor_noise(level, Ts) == pytest.approx([1e-4, 1e-4], rel=0.02)
    # what a filter state takes in per host sample
    injected = readings[1:] - board.host_pole(Ts) * readings[:-1]
    assert injected.var(axis=0) == pytest.approx(
        board.noise_injection(Ts) * 1e-8 * np.ones(2), rel=0.02
    )
