"""Coil commands in either message type: data[i] and effort[i] on the command topics only."""

from maglev_ros.bags import parse_channel
from maglev_ros.bags.channels import FieldRef, unit_of
from maglev_ros.bags.command_fields import command_alias, resolve_channel, resolve_ref

JOINT, ARRAY = 'sensor_msgs/msg/JointState', 'std_msgs/msg/Float64MultiArray'
COMMAND, EXCITATION = '/maglev/currents/command', '/maglev/currents/excitation'


def test_old_and_new_spellings_read_either_type():
    old, new = FieldRef(COMMAND, ('data', 2)), FieldRef(COMMAND, ('effort', 2))
    assert resolve_ref(old, JOINT) == new and resolve_ref(new, ARRAY) == old
    assert resolve_ref(old, ARRAY) == old and resolve_ref(new, JOINT) == new
    excitation = FieldRef(EXCITATION, ('data', 0))
    assert resolve_ref(excitation, JOINT) == FieldRef(EXCITATION, ('effort', 0))


def test_other_topics_and_paths_are_left_as_written():
    currents = FieldRef('/maglev/currents', ('data', 0))
    assert command_alias(currents) is None and resolve_ref(currents, JOINT) == currents
    header = FieldRef(COMMAND, ('header', 'stamp', 'sec'))
    assert command_alias(header) is None and resolve_ref(header, JOINT) == header
    assert command_alias(FieldRef(COMMAND, ('position', 0))) is None


def test_a_channel_keeps_its_name_and_its_unit():
    chan = parse_channel(f'ux=0.5*{COMMAND}:data[0]-0.5*{COMMAND}:data[1]')
    resolved = resolve_channel(chan, lambda topic: JOINT)
    assert resolved.name == 'ux' and resolved.spec == chan.spec
    assert [ref.path for _, ref in resolved.terms] == [('effort', 0), ('effort', 1)]
    assert [c for c, _ in resolved.terms] == [0.5, -0.5]
    assert unit_of(resolved) == unit_of(chan) == 'A'
