"""Sampled simulation vs solve_ivp, crashes, rigid-body invariants, coil and sensor effects."""

import numpy as np
import pytest

from maglev_ros.physics.kernels import rotation_matrix
from maglev_ros.physics.model import MaggyModel, make_model
from maglev_ros.physics.parameters import load_parameters
from maglev_ros.physics.simulation import (
    CoilDynamics,
    SensorEffects,
    SimulationCrashedError,
    Simulator,
    simulate_reference,
)

RATE = 5000.0


@pytest.mark.parametrize('name', ['maggy_v2', 'maggy_v4'])
def test_vertical_oscillation_matches_solve_ivp(name):
    model = make_model(name)
    sim = Simulator(model, sample_rate=RATE)
    x0 = sim.state
    x0[2] += 1e-3
    inputs = np.zeros((int(RATE), 4))
    fixed = sim.run(inputs, x0=x0)
    reference = simulate_reference(model, x0, inputs, 1 / RATE, rtol=1e-10)
    assert not fixed.crashed and not reference.crashed
    assert np.ptp(fixed.x[:, 2]) > 1.5e-3  # it really oscillates
    assert np.max(np.abs(fixed.x[:, :3] - reference.x[:, :3])) < 1e-6


def test_general_small_perturbation_matches_solve_ivp(v2, v2_equilibrium):
    rng = np.random.default_rng(7)
    x0 = v2_equilibrium + rng.normal(size=12) * np.repeat([2e-4, 5e-3, 5e-3, 5e-2], 3)
    inputs = np.zeros((int(0.1 * RATE), 4))
    fixed = Simulator(v2, sample_rate=RATE).run(inputs, x0=x0)
    reference = simulate_reference(v2, x0, inputs, 1 / RATE, rtol=1e-10)
    assert np.max(np.abs(fixed.x[-1] - x0)) > 1e-3  # it moved
    assert np.max(np.abs(fixed.x[:, :3] - reference.x[:, :3])) < 1e-6


def test_with_inputs_matches_solve_ivp(v2, v2_equilibrium):
    rng = np.random.default_rng(8)
    inputs = np.repeat(rng.choice([-0.05, 0.05], size=(50, 4)), 10, axis=0)  # ZOH segments
    fixed = Simulator(v2, sample_rate=RATE).run(inputs, x0=v2_equilibrium)
    reference = simulate_reference(v2, v2_equilibrium, inputs, 1 / RATE, rtol=1e-10)
    assert np.max(np.abs(fixed.x[:, :3] - reference.x[:, :3])) < 1e-6


def test_open_loop_ends_in_a_reported_crash(v2, v2_equilibrium):
    x0 = v2_equilibrium.copy()
    x0[0] += 1e-4
    sim = Simulator(v2, sample_rate=RATE)
    result = sim.run(np.zeros((int(2 * RATE), 4)), x0=x0)
    assert result.crashed and result.status == 'crashed'
    assert result.reason in ('touched the base', 'left the workspace')
    assert 0 < result.crash_time < 2.0
    assert np.all(np.isfinite(result.x)) and np.all(np.isfinite(result.crash_state))
    assert np.all(np.isfinite(result.y))
    assert result.crash_time == pytest.approx(result.t[-1] + 1 / RATE)
    with pytest.raises(SimulationCrashedError, match=r'crashed at t = .* reset it first'):
        sim.step(np.zeros(4))
    sim.reset(v2_equilibrium)
    assert not sim.crashed
    assert np.all(np.isfinite(sim.step(np.zeros(4))))


def test_reference_path_reports_the_crash_too(v2, v2_equilibrium):
    x0 = v2_equilibrium.copy()
    x0[0] += 1e-3
    result = simulate_reference(v2, x0, np.zeros((int(RATE), 4)), 1 / RATE, rtol=1e-8)
    assert result.crashed and result.crash_time < 1.0


def test_step_and_run_agree(v2, v2_equilibrium):
    rng = np.random.default_rng(2)
    inputs = rng.normal(size=(200, 4)) * 0.05
    sim = Simulator(v2, sample_rate=RATE)
    sim.reset(v2_equilibrium)
    stepped = np.array([sim.step(u) for u in inputs])
    state = sim.state
    ran = Simulator(v2, sample_rate=RATE).run(inputs, x0=v2_equilibrium)
    np.testing.assert_array_equal(stepped, ran.y[1:])
    np.testing.assert_array_equal(state, ran.x[-1])
    np.testing.assert_allclose(ran.y[0], v2.measurement(v2_equilibrium), rtol=0, atol=0)


def test_free_rigid_body_conserves_momentum_energy_and_body_spin():
    params = load_parameters('maggy_v2').without_base()
    model = MaggyModel(params)
    x0 = np.zeros(12)
    x0[2] = 0.05
    x0[3], x0[4] = 0.3, -0.2
    x0[9:12] = [2.0, -1.5, 10.0]
    sim = Simulator(model, sample_rate=RATE, check_crash=False, x0=x0)
    result = sim.run(np.zeros((int(RATE), 0)))
    inertia = np.array(params.magnet.inertia)

    def momentum(x):
        return rotation_matrix(x[3], x[4], x[5]) @ (inertia * x[9:12])

    def energy(x):
        return 0.5 * np.sum(inertia * x[9:12] ** 2)

    l0, e0 = momentum(x0), energy(x0)
    assert np.max(np.abs(result.x[:, 3:6] - x0[3:6])) > 0.1  # it tumbles
    for x in result.x[::250]:
        assert np.linalg.norm(momentum(x) - l0) / np.linalg.norm(l0) < 1e-9
        assert abs(energy(x) - e0) / e0 < 1e-9
    np.testing.assert_allclose(result.x[:, 11], x0[11], rtol=1e-12)
    # it falls freely meanwhile
    t = result.t[-1]
    assert result.x[-1, 2] == pytest.approx(0.05 - 0.5 * 9.81 * t**2, rel=1e-9)


def test_published_kinematics_drift_away_from_zero_angles():
    params = load_parameters('maggy_v2').without_base()
    x0 = np.zeros(12)
    x0[3], x0[4] = 0.3, -0.2
    x0[9:12] = [2.0, -1.5, 10.0]
    rigid = Simulator(MaggyModel(params), check_crash=False, x0=x0).run(np.zeros((500, 0)))
    published = Simulator(
        make_model(params, kinematics='published'), check_crash=False, x0=x0
    ).run(np.zeros((500, 0)))
    assert np.max(np.abs(rigid.x[:, 3:6] - published.x[:, 3:6])) > 1e-2


def test_coil_dynamics_follow_l_over_r_and_saturate(v2, v2_equilibrium):
    coil = CoilDynamics('current', resistance=3.0, inductance=0.006, supply_voltage=12.0)
    sim = Simulator(v2, sample_rate=RATE, coil=coil, check_crash=False, x0=v2_equilibrium)
    command = np.array([1.0, -0.5, 10.0, 0.0])  # 10 A needs 30 V: clipped at 12 V
    tau = 0.006 / 3.0
    currents = []
    for _ in range(int(2 * tau * RATE)):
        sim.step(command)
        currents.append(sim.currents)
    t = np.arange(1, len(currents) + 1) / RATE
    expected = np.outer(1 - np.exp(-t / tau), [1.0, -0.5, 4.0, 0.0])
    np.testing.assert_allclose(np.array(currents), expected, rtol=1e-5, atol=1e-9)


def test_coil_drive_modes():
    with pytest.raises(ValueError, match='drive must be one of'):
        CoilDynamics('pwm')
    with pytest.raises(ValueError, match='inductance must be positive'):
        CoilDynamics('duty', inductance=0.0)


def test_sensor_effects_are_seeded_and_applied(v2, v2_equilibrium):
    effects = SensorEffects(noise_rms=1e-4, quantization=1e-4, offset=2e-4, delay_samples=1)
    inputs = np.zeros((20, 4))
    a = Simulator(v2, sensor=effects, seed=3).run(inputs, x0=v2_equilibrium)
    b = Simulator(v2, sensor=effects, seed=3).run(inputs, x0=v2_equilibrium)
    c = Simulator(v2, sensor=effects, seed=4).run(inputs, x0=v2_equilibrium)
    np.testing.assert_array_equal(a.y, b.y)
    assert not np.array_equal(a.y, c.y)
    lsb = a.y / 1e-4
    np.testing.assert_allclose(lsb, np.round(lsb), atol=1e-9)
    ideal = Simulator(v2, sensor=SensorEffects(delay_samples=1)).run(inputs, x0=v2_equilibrium)
    undelayed = Simulator(v2).run(inputs, x0=v2_equilibrium)
    np.testing.assert_array_equal(ideal.y[1:], undelayed.y[:-1])
    assert np.abs(np.mean(a.y - undelayed.y) - 2e-4) < 1e-4


def test_bad_simulator_arguments(v2, v2_equilibrium):
    with pytest.raises(ValueError, match='sample_rate must be positive'):
        Simulator(v2, sample_rate=0.0)
    with pytest.raises(ValueError, match='substeps must be an integer >= 1'):
        Simulator(v2, substeps=0)
    sim = Simulator(v2, x0=v2_equilibrium)
    with pytest.raises(ValueError, match=r'input must have 4 values'):
        sim.step([1.0, 2.0])
    with pytest.raises(ValueError, match='input must be finite'):
        sim.step([np.nan, 0, 0, 0])
    with pytest.raises(ValueError, match=r'inputs must have shape \(N, 4\)'):
        sim.run(np.zeros((3, 2)))


@pytest.mark.parametrize('field', ['fast', 'accurate'])
def test_fixed_and_absent_magnet_only_the_coils_move(field):
    model = make_model('maggy_v2', field=field)
    x0 = model.hover_state(0.0365)
    x0[0] = 0.003  # off-centre: a free magnet would fly away
    coil = CoilDynamics('current', resistance=3.0, inductance=0.004, supply_voltage=12.0)
    inputs = np.tile([0.5, -0.5, 0.2, -0.2], (50, 1))
    fixed = Simulator(model, coil=coil, x0=x0, magnet='fixed').run(inputs)
    absent = Simulator(model, coil=coil, x0=x0, magnet='absent').run(inputs)
    for result in (fixed, absent):
        assert not result.crashed
        np.testing.assert_array_equal(result.x, np.tile(x0, (51, 1)))
        tau = 0.004 / 3.0
        t = result.t[1:]
        np.testing.assert_allclose(
            result.currents[1:, 0], 0.5 * (1 - np.exp(-t / tau)), rtol=1e-12
        )
    # the difference of the readings is exactly the levitating magnet's own field
    positions = np.array([s.position for s in model.params.sensors])
    np.testing.assert_allclose(
        fixed.y - absent.y,
        np.tile(model.magnet_field_at(positions, x0).ravel(), (51, 1)),
        rtol=1e-9,
        atol=1e-15,
    )
    with pytest.raises(ValueError, match='magnet must be one of free, fixed, absent'):
        Simulator(model, magnet='glued')


@pytest.mark.parametrize('field', ['fast', 'accurate'])
def test_a_held_magnet_stays_put_until_its_release_then_moves_as_a_free_one(field):
    model = make_model('maggy_v2', field=field)
    x0 = model.hover_state(0.0365)
    x0[0] = 0.003  # off-centre: a free magnet flies away
    inputs = np.tile([0.5, -0.5, 0.2, -0.2], (14, 1))
    held = Simulator(model, sample_rate=RATE, x0=x0, hold=8 / RATE)
    assert held.hold_samples == 8 and held.held
    stepped = np.array([held.step(u) for u in inputs])
    assert not held.held
    ran = held.run(inputs)
    np.testing.assert_array_equal(ran.x[:9], np.tile(x0, (9, 1)))  # held through sample 8
    np.testing.assert_array_equal(stepped, ran.y[1:])  # stepping and a run release alike
    # released: from the held state at sample 8 on, the motion of a free magnet
    free = Simulator(model, sample_rate=RATE).run(inputs[8:], x0=x0)
    assert np.abs(free.x[-1] - x0).max() > 1e-6  # it moves
    np.testing.assert_array_equal(ran.x[8:], free.x)
    # a crash while held is no crash; after the release it is
    low = x0.copy()
    low[2] = 0.0  # into the base
    assert Simulator(model, x0=low, hold=1.0).run(inputs).status == 'ok'
    assert Simulator(model, x0=low, hold=1 / RATE).run(inputs).crashed
    # each reset holds it again; a fixed magnet is not released
    held.reset()
    assert held.held
    assert Simulator(model, x0=x0, magnet='fixed', hold=1.0).hold_samples == 0
    with pytest.raises(ValueError, match=r'hold must be a finite number of seconds >= 0'):
        Simulator(model, hold=-1.0)
