"""Building the simulator of a configuration, without ROS: errors name the value."""

import dataclasses

import pytest

from maglev_ros.physics.simulator_config import (
    SimulatorConfig,
    SimulatorConfigError,
    check_initial_state,
    check_parameter_set,
    check_sensor_indices,
    make_simulator,
)

BASE = SimulatorConfig(
    params='maggy_v2',
    field_model='fast',
    torque='true',
    kinematics='rigid',
    sample_rate=5000.0,
    substeps=1,
    magnet='free',
    initial_state=None,
    coil_dynamics=True,
    sensor_noise=0.0,
    sensor_quantization=0.0,
    sensor_delay=1,
    seed=0,
    mode='lockstep',
    command_timeout=1.0,
    pace_period=0.001,
    start_paused=False,
    start_subscribers=0,
    sensors=(),
    publish_state=True,
    publish_clock=True,
    marker_rate=0.0,
    diagnostics_period=1.0,
)


def test_builds_the_configured_simulator():
    sim = make_simulator(dataclasses.replace(BASE, sample_rate=2000.0, sensor_delay=2))
    assert sim.sample_rate == 2000.0 and sim.coil is not None
    assert make_simulator(dataclasses.replace(BASE, coil_dynamics=False)).coil is None


@pytest.mark.parametrize(
    ('changes', 'message'),
    [
        ({'params': 'maggy_v9'}, "params 'maggy_v9': "),
        ({'sensors': (0, 7)}, r'sensors must be indices below \d+ \(maggy_v2 has'),
    ],
)
def test_errors_name_the_value(changes, message):
    with pytest.raises(SimulatorConfigError, match=message):
        make_simulator(dataclasses.replace(BASE, **changes))


def test_summary_says_what_runs():
    line = dataclasses.replace(BASE, sensor_noise=2e-5, seed=3).summary('maggy_v2', (0, 1, 2))
    assert line == (
        'maggy_v2 (fast field), magnet free, lockstep at 5000 Hz, sensors [0, 1, 2], coil '
        'dynamics on, sensor delay 1, noise 2e-05 T, seed 3'
    )
    waiting = dataclasses.replace(
        BASE, mode='realtime', start_paused=True, wait_for_controller=True
    )
    assert waiting.summary('maggy_v2', (0,)).endswith(', paused, waiting for a first command')
    recorded = dataclasses.replace(waiting, start_reader='maglev_recorder')
    assert recorded.summary('maggy_v2', (0,)).endswith(
        'waiting for a first command and for maglev_recorder to read maglev/currents/command'
    )
    # real time without wait_for_controller starts at once: no wait to announce
    at_once = dataclasses.replace(recorded, wait_for_controller=False)
    assert 'maglev_recorder' not in at_once.summary('maggy_v2', (0,))
    # a free magnet held after the start says so; a fixed one has nothing to release
    held = dataclasses.replace(BASE, hold=2.0)
    assert held.summary('maggy_v2', (0,)).endswith(', the magnet held 2 s after the start')
    assert 'held' not in dataclasses.replace(held, magnet='fixed').summary('maggy_v2', (0,))


def test_the_hold_reaches_the_simulator():
    assert make_simulator(dataclasses.replace(BASE, hold=0.01)).hold_samples == 50
    assert make_simulator(BASE).hold_samples == 0


@pytest.mark.parametrize(
    ('check', 'value', 'message'),
    [
        (
            check_initial_state,
            (0.0,) * 3,
            r'x0 must be 12 finite numbers .*, got \[0.0, 0.0, 0.0\]',
        ),
        (check_initial_state, (float('nan'),) * 12, 'x0 must be 12 finite numbers'),
        (check_sensor_indices, (0, 0), r'x0 must be distinct sensor indices >= 0, got \[0, 0\]'),
        (check_sensor_indices, (-1,), 'x0 must be distinct sensor indices >= 0'),
        (check_parameter_set, '', 'x0 must name a parameter set, got an empty string'),
    ],
)
def test_checks_name_the_parameter_and_raise_the_error_asked_for(check, value, message):
    with pytest.raises(SimulatorConfigError, match=message):
        check('x0', value)

    class NodeError(ValueError):
        pass

    with pytest.raises(NodeError, match=message):
        check('x0', value, error=NodeError)


def test_checks_pass_good_values():
    assert check_initial_state('x0', ()) is None  # the first equilibrium
    assert check_initial_state('x0', (0.0,) * 12) == (0.0,) * 12
    assert check_sensor_indices('s', (2, 0)) == (2, 0)
    assert check_parameter_set('p', 'maggy_v4') == 'maggy_v4'
