"""Message builders and decoders of the Maggy graph: the stamped JointState command."""

import re

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from maglev_ros.nodes.messages import (
    CommandMessageError,
    command_currents,
    command_message,
    stamp_ns,
)


def test_command_round_trip_with_names_stamp_and_efforts():
    msg = command_message(1_500_000_200_000, [0.5, -0.5, 0.25, -0.25])
    assert list(msg.name) == ['x+', 'x-', 'y+', 'y-'] and msg.header.frame_id == ''
    assert len(msg.position) == 0 and len(msg.velocity) == 0
    got = deserialize_message(serialize_message(msg), JointState)
    assert stamp_ns(got) == 1_500_000_200_000
    np.testing.assert_array_equal(command_currents(got), [0.5, -0.5, 0.25, -0.25])


def test_a_command_without_names_is_taken_in_coil_order():
    np.testing.assert_array_equal(
        command_currents(JointState(effort=[1.0, 2.0, 3.0, 4.0])), [1, 2, 3, 4]
    )


def test_the_coils_named_in_another_order_are_put_in_coil_order():
    msg = JointState(name=['y-', 'x+', 'y+', 'x-'], effort=[4.0, 1.0, 3.0, 2.0])
    np.testing.assert_array_equal(command_currents(msg), [1.0, 2.0, 3.0, 4.0])


@pytest.mark.parametrize(
    'names', [['x+', 'x-', 'y+'], ['a', 'b', 'c', 'd'], ['x+', 'x+', 'y+', 'y-']]
)
def test_other_names_are_refused_naming_them(names):
    msg = JointState(name=names, effort=[0.0] * len(names))
    with pytest.raises(CommandMessageError, match=re.escape(f'got names {names}')):
        command_currents(msg)
