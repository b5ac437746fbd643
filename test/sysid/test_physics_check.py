"""The physics check: sampled linearisation and frequency-response comparison."""

from types import SimpleNamespace

import numpy as np
import pytest

from maglev_ros.physics import CoilDynamics, SensorEffects, Simulator, linearize, make_model
from maglev_ros.sysid import PolyModel, make_orders
from maglev_ros.sysid.physics_check import PhysicsCheckError, compare_response, local_plant

TS = 2e-4


def first_order(a, b_w, c, d):
    """dx = -a x + b . i, y = c x + d . i with 4 coils (a < 0: unstable)."""
    return SimpleNamespace(
        A=np.array([[-a]]),
        B=np.array([b_w]),
        C=np.array([[c]]),
        D=np.array([d]),
        outputs=('Bx_0',),
    )


def arx_of_first_order(p, g, dd, delay):
    """G = z^-d (g / (z - p) + dd z^-1) as ARX.

    A = 1 - p q^-1, B = (g + dd) q^-(1+d) - p dd q^-(2+d).
    """
    orders = make_orders(1, 1, na=1, nb=2, nk=1 + delay)
    return PolyModel('arx', orders, np.array([-p, g + dd, -p * dd]), TS, np.eye(1))


@pytest.mark.parametrize('a', [50.0, -30.0])  # stable and unstable (as Maggy's x mode)
@pytest.mark.parametrize('delay', [0, 1])
def test_known_first_order_system(a, delay):
    linear = first_order(a, [2.0, -1.0, 0.3, 0.0], 4.0, [1e-3, -2e-3, 0.0, 5.0])
    plant = local_plant(linear, TS, 'Bx_0', 'x', delay)
    # input u on x+, -u on x-: b = 2 + 1 = 3, d = 1e-3 + 2e-3
    p = np.exp(-a * TS)
    g = 4.0 * 3.0 * (1 - p) / a
    f = np.geomspace(1.0, 2000.0, 50)
    z = np.exp(2j * np.pi * f * TS)
    expected = z ** (-delay) * (g / (z - p) + 3e-3 / z)
    np.testing.assert_allclose(plant.freqresp(f), expected, rtol=1e-10)
    exact = arx_of_first_order(p, g, 3e-3, delay)
    same = compare_response(exact, plant, (1.0, 2000.0))
    assert same.max_db < 1e-9 and same.max_deg < 1e-7
    late = compare_response(arx_of_first_order(p, g, 3e-3, delay + 1), plant, (1.0, 2000.0))
    # one sample more delay: unit gain ratio, phase -360 f Ts
    assert late.max_db < 1e-9
    np.testing.assert_allclose(late.phase_deg, -360.0 * late.frequencies * TS, atol=1e-7)
    assert late.max_deg == pytest.approx(360.0 * 2000.0 * TS)
    assert 'max 0.00 dB / 144.0 deg' in late.summary()


def test_gain_error_in_db():
    linear = first_order(50.0, [1.0, -1.0, 0, 0], 1.0, [0, 0, 0, 0])
    plant = local_plant(linear, TS, 0, 'x', 1)
    p = np.exp(-50.0 * TS)
    g = 2.0 * (1 - p) / 50.0
    off = compare_response(arx_of_first_order(p, 1.1 * g, 0.0, 1), plant, (1, 100), n=20)
    np.testing.assert_allclose(off.gain_db, 20 * np.log10(1.1), rtol=1e-9)
    assert off.rms_db == pytest.approx(20 * np.log10(1.1)) and off.max_deg < 1e-9
    assert off.within(0.9, 1.0) and not off.within(0.8, 1.0)


@pytest.mark.parametrize('coils', [False, True])
def test_maggy_linearisation_matches_the_simulator(coils):
    """The sampled linearisation's pulse response is the nonlinear simulator's (V2, x pair)."""
    model = make_model('maggy_v2')
    coil = CoilDynamics.from_parameters(model.params) if coils else None
    sim = Simulator(model, 1 / TS, coil=coil, sensor=SensorEffects(delay_samples=1))
    readings = [sim.reset()]
    eps = 1e-3  # A: small enough to stay linear over 6 ms of the unstable mode
    for t in range(30):
        readings.append(sim.step([eps, -eps, 0, 0] if t == 0 else np.zeros(4)))
    pulse = (np.array(readings)[:, 0] - readings[0][0]) / eps
    tau = coil.inductance / coil.resistance if coils else None
    plant = local_plant(linearize(model).reduced(), TS, 'Bx_0', 'x', 1, tau)
    expected = plant.impulse(31)
    assert pulse[:2].tolist() == [0.0, 0.0] and expected[:2].tolist() == [0.0, 0.0]
    np.testing.assert_allclose(pulse, expected, atol=1e-4 * np.abs(expected).max())


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'output': 'Bq_0'}, "unknown output 'Bq_0'"),
        ({'output': 3}, 'out of range'),
        ({'pair': 'z'}, "unknown pair 'z'"),
        ({'pair': (1.0, 2.0)}, 'must have 4 values'),
        ({'delay_samples': -1}, 'delay_samples must be an integer >= 0'),
        ({'coil_time_constant': 0.0}, 'coil_time_constant must be positive'),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(PhysicsCheckError, match=match):
        local_plant(first_order(1.0, [1, 0, 0, 0], 1.0, [0, 0, 0, 0]), TS, **kwargs)
    with pytest.raises(PhysicsCheckError, match='Ts must be'):
        local_plant(first_order(1.0, [1, 0, 0, 0], 1.0, [0, 0, 0, 0]), 0.0)


def test_bad_band():
    plant = local_plant(first_order(1.0, [1, -1, 0, 0], 1.0, [0, 0, 0, 0]), TS)
    with pytest.raises(PhysicsCheckError, match='band must be'):
        compare_response(plant, plant, (10.0, 5.0))


def test_undamped_resonances_are_left_out():
    """The linearised V2 magnet has undamped modes: 14.3 Hz shows in the x path, 6.6 Hz not."""
    plant = local_plant(linearize(make_model('maggy_v2')).reduced(), TS, 'Bx_0', 'x', 1)
    cancelled, resonance = plant.resonances()
    assert 6.4 < cancelled < 6.8 and 14.0 < resonance < 14.6
    near = compare_response(plant, plant, (5.0, 50.0), n=400)
    assert near.excluded == (resonance,)
    assert np.all(np.abs(near.frequencies - resonance) > 1.0)
    assert 'without +-1 Hz around the undamped resonance(s) at 14.30 Hz' in near.summary()
    kept = compare_response(plant, plant, (5.0, 50.0), n=400, resonance_width=0.0)
    assert kept.excluded == () and kept.frequencies.size == 400
    with pytest.raises(PhysicsCheckError, match='nothing left to compare'):
        compare_response(plant, plant, (14.0, 14.5))


def test_a_notch_where_a_direct_term_cancels_the_motion_is_left_out():
    """A board whose y pair leaves 0.025 mT/A against the magnet's field: the two cancel
    near 10 Hz (a zero pair of damping 0.005); the pole-cancelled zeros (6.6, 13.0,
    14.3 Hz) do not show and are not notches."""
    from maglev_ros.loop.v4x_pc_setup import board_model
    from maglev_ros.physics.board_processing import BoardProcessing
    from maglev_ros.sysid.board_check import board_local_plant

    model = board_model('maggy_v2', 0)
    lin = linearize(model).reduced()
    pairs = np.array([[0.0, 0.0], [0.0, 2.54e-5], [0.0, 0.0]])
    notched = board_local_plant(
        lin, 1e-3, 'By_0', 'y', BoardProcessing.from_model(model, pairs=pairs)
    )
    [notch] = [f for f in notched.antiresonances() if 5.0 < f < 12.0 and abs(f - 6.59) > 0.1]
    assert 9.5 < notch < 10.5
    near = compare_response(notched, notched, (1.0, 12.0), n=300)
    assert near.notches == (notch,) and np.all(np.abs(near.frequencies - notch) > 1.0)
    assert f'without +-1 Hz around the notch(es) at {notch:.2f} Hz' in near.summary()
    exact = board_local_plant(lin, 1e-3, 'By_0', 'y', BoardProcessing.from_model(model))
    assert compare_response(exact, exact, (1.0, 12.0), n=300).notches == ()


def test_the_unstable_mode_shows_once_and_a_mirrored_pole_is_named():
    """An unstable first-order mode (30 1/s, as Maggy's x mode): a model that puts the
    stable pole ``1/p`` in its place has the same gain but misses it, and the check says
    so."""
    linear = first_order(-30.0, [1.0, -1.0, 0.0, 0.0], 1.0, [0.0, 0.0, 0.0, 0.0])
    plant = local_plant(linear, TS, 'Bx_0', 'x', 0)
    np.testing.assert_allclose(plant.unstable_rates(), [30.0], rtol=1e-9)
    p = np.exp(30.0 * TS)
    g = 2.0 * (1 - p) / -30.0
    right = compare_response(arx_of_first_order(p, g, 0.0, 0), plant, (1.0, 100.0))
    assert right.unstable_model == pytest.approx((30.0,)) and not right.misses_instability
    assert right.within(0.01, 0.01) and 'unstable' not in right.summary()
    # the mirror image: pole 1/p, gain g/p: |G| the same on the whole unit circle, the
    # phase 180 - 2 atan(2 pi f / 30) deg off (156 deg at 1 Hz)
    mirrored = arx_of_first_order(1 / p, g / p, 0.0, 0)
    check = compare_response(mirrored, plant, (1.0, 100.0))
    assert check.max_db < 1e-6 and check.max_deg == pytest.approx(156.4, abs=0.5)
    assert check.unstable_model == () and check.misses_instability
    assert not check.within(1.0, 360.0)
    assert check.brief().endswith('(no unstable pole)')
    assert 'the model misses an unstable mode (physics / model: 30 / none 1/s)' in check.summary()
    # a band above the mode's corner (4.8 Hz) does not see it: not flagged, the phase says it
    above = compare_response(mirrored, plant, (10.0, 100.0))
    assert not above.misses_instability and 40.0 < above.max_deg < 60.0


def test_the_symmetric_tilt_modes_count_once_in_each_pair_path():
    model = make_model('maggy_v2')
    lin = linearize(model).reduced()
    for pair in ('x', 'y'):
        plant = local_plant(lin, TS, f'B{pair}_0', pair, 1)
        rates = plant.unstable_rates()
        assert rates.shape == (1,) and 20.0 < rates[0] < 60.0, rates
        unstable = np.abs(np.linalg.eigvals(plant.A)) > 1 + 1e-9
        assert np.count_nonzero(unstable) == 2  # x and y, the same rate
