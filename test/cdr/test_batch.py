"""Messages serialised by patching CDR bytes equal rclpy's own serialisation.

Compared after deserialisation, with the length of the exact CDR bytes:
rclpy leaves the alignment padding after a string uninitialised, so those
bytes differ from run to run, and its buffers can end in a few bytes of
slack (Fast CDR's size estimate aligns even empty sequences: a JointState
without positions and velocities is 100 bytes, in a 108-byte buffer).
"""

import struct

import numpy as np
import pytest
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.bags.typestore import cdr_deserializer
from maglev_ros.cdr import (
    currents_layout,
    default_message,
    field_layout,
    jazzy_typestore,
    odometry_layout,
    raw_layout,
)
from maglev_ros.cdr.batch import RawMessageBatch, SampleSerialiser, sensor_sample_serialiser
from maglev_ros.nodes import contract

COILS = contract.COIL_NAMES


def true_state_layout():
    """The true-state odometry layout of the contract's frames."""
    return odometry_layout(contract.BASE_FRAME, contract.MAGNET_FRAME)


N = 50


@pytest.fixture
def stamps():
    rng = np.random.default_rng(0)
    t_ns = rng.integers(0, 2**31 - 1, N) * 1_000_000_000 + rng.integers(0, 10**9, N)
    t_ns[:2] = 0, 2**31 * 1_000_000_000 - 1  # the extremes of an int32 sec
    return t_ns


def exact_cdr(msg) -> bytes:
    """The CDR bytes of an rclpy message without rclpy's trailing slack (rosbags)."""
    cls = type(msg)
    msgtype = f'{cls.__module__.split(".")[0]}/msg/{cls.__name__}'
    plain = cdr_deserializer(jazzy_typestore(), msgtype)(bytes(serialize_message(msg)))
    return bytes(jazzy_typestore().serialize_cdr(plain, msgtype))


def check(messages, cls, build):
    """Each serialised message deserialises to ``build(i)`` and has its length."""
    for i, raw in enumerate(messages):
        expected = build(i)
        assert deserialize_message(raw, cls) == expected
        assert len(raw) == len(exact_cdr(expected))


def test_batches_equal_message_objects(stamps):
    rng = np.random.default_rng(1)
    field = rng.normal(0.0, 0.05, (N, 3))
    currents = rng.normal(0.0, 1.0, (N, 4))
    states = rng.normal(0.0, 0.01, (N, 12))
    odometry = np.array([contract.odometry_values(x) for x in states])
    t_ns = stamps.tolist()
    fields = RawMessageBatch(field_layout(contract.sensor_frame(11)))
    check(
        fields.serialise(stamps, field),
        MagneticField,
        lambda i: contract.field_message(11, t_ns[i], field[i]),
    )
    check(
        RawMessageBatch(currents_layout(COILS)).serialise(stamps, currents),
        JointState,
        lambda i: contract.currents_message(t_ns[i], currents[i]),
    )
    check(
        RawMessageBatch(true_state_layout()).serialise(stamps, odometry),
        Odometry,
        lambda i: contract.odometry_message(t_ns[i], states[i]),
    )


def test_sample_serialiser_interleaves_the_parts_per_sample(stamps):
    rng = np.random.default_rng(2)
    fields = rng.normal(0.0, 0.05, (N, 2, 3))
    currents = rng.normal(0.0, 1.0, (N, 4))
    serialiser = SampleSerialiser(
        [RawMessageBatch(field_layout(contract.sensor_frame(k))) for k in (0, 1)]
        + [RawMessageBatch(currents_layout(COILS))]
    )
    for n in (N, 5, N):  # reused rows per burst length keep nothing from earlier calls
        messages = serialiser.serialise(stamps[:n], [fields[:n, 0], fields[:n, 1], currents[:n]])
        assert len(messages) == 3 * n
        for i in range(n):
            t_ns = int(stamps[i])
            for k in range(2):
                got = deserialize_message(messages[3 * i + k], MagneticField)
                assert got == contract.field_message(k, t_ns, fields[i, k])
            joint = deserialize_message(messages[3 * i + 2], JointState)
            assert joint == contract.currents_message(t_ns, currents[i])


def test_sensor_sample_serialiser_is_the_drivers_sample(stamps):
    rng = np.random.default_rng(4)
    values = rng.normal(0.0, 0.05, (N, 3 * 2 + 4))  # two sensors' fields, then currents
    frames = ('board_a', 'board_b')
    messages = sensor_sample_serialiser(frames).serialise(stamps, values)
    assert len(messages) == 3 * N
    for i in range(N):
        t_ns = int(stamps[i])
        for k in range(2):
            expected = contract.field_message(k, t_ns, values[i, 3 * k : 3 * k + 3])
            expected.header.frame_id = frames[k]
            assert deserialize_message(messages[3 * i + k], MagneticField) == expected
        joint = deserialize_message(messages[3 * i + 2], JointState)
        assert joint == contract.currents_message(t_ns, values[i, 6:])


def test_burst_of_one_equals_message_objects():
    rng = np.random.default_rng(3)
    batch = RawMessageBatch(true_state_layout())
    for _ in range(20):
        t_ns = int(rng.integers(0, 2_000_000_000 * 10**9))  # sec within int32
        x = rng.normal(0.0, 0.01, 12)
        (got,) = batch.serialise(np.array([t_ns]), contract.odometry_values(x)[None, :])
        expected = contract.odometry_message(t_ns, x)
        check([got], Odometry, lambda i, expected=expected: expected)


@pytest.mark.parametrize(
    'values',
    [
        [('effort', 2)],  # beyond the two efforts of this template
        [('no_such_field',)],
        [('header', 'stamp', 'sec')],  # an int32, not a float64
    ],
)
def test_layout_refuses_what_it_cannot_locate(values):
    msg = default_message('sensor_msgs/msg/JointState')
    msg.name, msg.effort = ['a'], np.zeros(2)
    with pytest.raises(ValueError, match='cannot locate'):
        raw_layout(msg, 'sensor_msgs/msg/JointState', values)


def test_layout_offsets_match_the_walked_bytes():
    layout = currents_layout(COILS)
    raw = bytearray(layout.template)
    for j, offset in enumerate(layout.value_offsets):
        struct.pack_into('<d', raw, offset, j + 0.5)
    struct.pack_into('<iI', raw, layout.stamp_offset, 7, 9)
    msg = deserialize_message(bytes(raw), JointState)
    assert list(msg.effort) == [0.5, 1.5, 2.5, 3.5]
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (7, 9)
    assert list(msg.name) == list(contract.COIL_NAMES)


def test_values_as_one_matrix_and_wrong_shapes(stamps):
    serialiser = SampleSerialiser(
        [RawMessageBatch(field_layout('f')), RawMessageBatch(currents_layout(COILS))]
    )
    values = np.random.default_rng(4).normal(size=(N, 7))
    as_matrix = serialiser.serialise(stamps, values)
    as_parts = serialiser.serialise(stamps, [values[:, :3], values[:, 3:]])
    assert [
        deserialize_message(m, JointState if i % 2 else MagneticField)
        for i, m in enumerate(as_matrix)
    ] == [
        deserialize_message(m, JointState if i % 2 else MagneticField)
        for i, m in enumerate(as_parts)
    ]
    with pytest.raises(ValueError, match=r'values must have shape \(50, 7\)'):
        serialiser.serialise(stamps, values[:, :6])


@pytest.mark.parametrize('values', [[0.0, 0.0, 0.0, 0.0], [1.0, -0.25, 3e-7, -1.0], [0.5]])
def test_float_array_prefix_plus_values_is_the_message(values):
    """The command's bytes (template + doubles) equal rclpy's Float64MultiArray, and read back."""
    from std_msgs.msg import Float64MultiArray

    from maglev_ros.cdr.templates import float_array_prefix

    raw = float_array_prefix(len(values)) + struct.pack(f'<{len(values)}d', *values)
    msg = Float64MultiArray()
    msg.data = values
    ref = bytes(serialize_message(msg))
    # equal but for the 4 alignment bytes before the doubles (rclpy leaves them unset)
    assert len(raw) == len(ref) and raw[:16] == ref[:16] and raw[20:] == ref[20:]
    assert list(deserialize_message(raw, Float64MultiArray).data) == values
