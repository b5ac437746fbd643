"""Node parameters in-process (issue 11, items 3, 4, 12; the real CLI: test/ros2cli)."""

from __future__ import annotations

import pytest
from rclpy.parameter import Parameter

from maglev_ros.nodes.driver import DriverParameterError, build_config
from maglev_ros.nodes.excitation import ExcitationNode
from maglev_ros.nodes.simulator import SimulatorNode, SimulatorParameterError


def test_integers_are_accepted_for_doubles(ctx):
    node = SimulatorNode(
        context=ctx,
        parameter_overrides=[
            Parameter('sample_rate', value=2000),
            Parameter('sensor_noise', value=0),
            Parameter('marker_rate', value=0),
            Parameter('start_paused', value=True),
            Parameter('magnet', value='fixed'),
        ],
    )
    try:
        cfg = node.config
        assert cfg.sample_rate == 2000.0 and isinstance(cfg.sample_rate, float)
        assert cfg.sensor_noise == 0.0 and isinstance(cfg.sensor_noise, float)
    finally:
        node.destroy_node()
    excite = ExcitationNode(
        context=ctx,
        parameter_overrides=[Parameter('amplitude', value=1), Parameter('band', value=[0, 1])],
    )
    try:
        assert excite.config.amplitude == 1.0 and isinstance(excite.config.amplitude, float)
        assert excite.config.band == (0.0, 1.0) and all(
            type(b) is float for b in excite.config.band
        )
    finally:
        excite.destroy_node()


def test_a_float_for_an_integer_is_one_clear_error(ctx):
    with pytest.raises(SimulatorParameterError, match=r'^seed must be an integer, got 1\.5$'):
        SimulatorNode(context=ctx, parameter_overrides=[Parameter('seed', value=1.5)])


def test_every_parameter_has_a_value(ctx):
    node = SimulatorNode(
        context=ctx,
        parameter_overrides=[
            Parameter('start_paused', value=True),
            Parameter('magnet', value='fixed'),
        ],
    )
    try:
        names = [n for n in node._parameters if n != 'use_sim_time']
        unset = [p.name for p in node.get_parameters(names) if p.type_ == Parameter.Type.NOT_SET]
        assert not unset  # ros2 param dump answers {} when one is unset
        assert node.get_parameter('initial_state').value in ([], ())
    finally:
        node.destroy_node()


def _driver_values(**changes):
    return {'port': '/dev/ttyACM0'} | changes


def test_driver_refuses_a_command_timeout_beyond_the_board_watchdog():
    assert build_config(_driver_values(command_timeout=1.0)).command_timeout == 1.0
    assert build_config(_driver_values(command_timeout=1)).command_timeout == 1.0
    with pytest.raises(
        DriverParameterError, match=r"command_timeout must be at most the firmware's 1 s watchdog"
    ):
        build_config(_driver_values(command_timeout=1.5))
