"""Building the simulator of a configuration, without ROS: errors name the value."""

import dataclasses

import pytest

from maglev_ros.physics.simulator_config import (
    SimulatorConfig,
    SimulatorConfigError,
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
