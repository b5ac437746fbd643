import numpy as np
import pytest
from bags.recordings import (
    COMMAND,
    CURRENTS,
    SENSOR,
    currents_msg,
    field_msg,
    lockstep_data,
    write_lockstep_bag,
)
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from maglev_ros.bags import BagReader, parse_channel
from maglev_ros.bags.extraction import read_topics
from maglev_ros.bags.typestore import cdr_deserializer, jazzy_typestore
from maglev_ros.cdr.layout import cdr_layout, decode_columns

STORE = jazzy_typestore()


def _by_deserializing(msgtype, raws, path):
    decode = cdr_deserializer(STORE, msgtype)
    out = []
    for raw in raws:
        obj = decode(raw)
        for part in path:
            obj = obj[part] if isinstance(part, int) else getattr(obj, part)
        out.append(obj)
    return np.array(out)


def _odometry(k):
    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 100 + k, 7 * k
    msg.header.frame_id, msg.child_frame_id = 'maglev_base', 'maglev_magnet'
    msg.pose.pose.position.z = 0.03 + 1e-4 * k
    msg.pose.covariance = [float(i + k) for i in range(36)]
    msg.twist.twist.angular.y = -0.5 * k
    return serialize_message(msg)


def _multiarray(k):
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label='coil', size=4, stride=4)]
    msg.layout.data_offset = 1
    msg.data = [float(k), -float(k), 0.5, 2.0**-k]
    return serialize_message(msg)


CASES = [
    (
        'sensor_msgs/msg/MagneticField',
        lambda k: field_msg(10**9 * k + 3, [k, 2.0 * k, -k]),
        [
            ('magnetic_field', 'x'),
            ('magnetic_field', 'z'),
            ('header', 'stamp', 'sec'),
            ('header', 'stamp', 'nanosec'),
            ('magnetic_field_covariance', 8),
        ],
    ),
    (
        'sensor_msgs/msg/JointState',
        lambda k: currents_msg(k, [k, 1.0, -k, 0.25]),
        [('effort', 0), ('effort', 3), ('header', 'stamp', 'nanosec')],
    ),
    (
        'std_msgs/msg/Float64MultiArray',
        _multiarray,
        [('data', 0), ('data', 3), ('layout', 'data_offset'), ('layout', 'dim', 0, 'size')],
    ),
    (
        'nav_msgs/msg/Odometry',
        _odometry,
        [
            ('pose', 'pose', 'position', 'z'),
            ('pose', 'covariance', 35),
            ('twist', 'twist', 'angular', 'y'),
            ('header', 'stamp', 'sec'),
        ],
    ),
]


@pytest.mark.parametrize(('msgtype', 'make', 'paths'), CASES)
def test_strided_reads_equal_deserialisation(msgtype, make, paths):
    raws = [make(k) for k in range(20)]
    layout = cdr_layout(STORE, msgtype, raws[0], paths)
    assert layout is not None
    columns = decode_columns(raws, layout, paths)
    for path, column in zip(paths, columns, strict=True):
        np.testing.assert_array_equal(column, _by_deserializing(msgtype, raws, path))


def test_different_layouts_fall_back():
    paths = [('magnetic_field', 'x')]
    raws = [field_msg(1, [1.0, 2.0, 3.0]), field_msg(2, [4.0, 5.0, 6.0])]
    layout = cdr_layout(STORE, 'sensor_msgs/msg/MagneticField', raws[0], paths)
    from sensor_msgs.msg import MagneticField

    other = MagneticField()
    other.header.frame_id = 'maglev_sensor_1x'  # 4 bytes longer: everything after moves
    assert decode_columns([raws[0], serialize_message(other)], layout, paths) is None
    short = MagneticField()
    short.header.frame_id = 'maglev_sensor_'  # one byte shorter, padding keeps the size
    assert len(serialize_message(short)) == len(raws[0])
    assert decode_columns([raws[0], serialize_message(short)], layout, paths) is None
    big = bytes(
        STORE.serialize_cdr(
            STORE.deserialize_cdr(raws[0], 'sensor_msgs/msg/MagneticField'),
            'sensor_msgs/msg/MagneticField',
            little_endian=False,
        )
    )
    assert cdr_layout(STORE, 'sensor_msgs/msg/MagneticField', big, paths) is None
    assert (
        cdr_layout(STORE, 'sensor_msgs/msg/JointState', currents_msg(1, [1.0]), [('effort', 3)])
        is None
    )  # index beyond the sequence


def test_fast_and_slow_paths_agree_on_a_bag(tmp_path):
    bag = write_lockstep_bag(tmp_path / 'run', lockstep_data(300, seed=3), 'sqlite3')
    specs = [
        'maglev/sensor_0/field:magnetic_field.y',
        'maglev/currents:effort[2]',
        'maglev/currents/command:data[1]',
    ]
    refs = {}
    for spec in specs:
        ref = parse_channel(spec).terms[0][1]
        refs[ref.topic] = [ref]
    with BagReader(bag) as reader:
        fast = read_topics(reader, refs)
        slow = read_topics(reader, refs, fast=False)
    for topic in (SENSOR, CURRENTS, COMMAND):
        np.testing.assert_array_equal(fast[topic].values, slow[topic].values)
        np.testing.assert_array_equal(fast[topic].stamps, slow[topic].stamps)
        assert fast[topic].clock == slow[topic].clock


@pytest.mark.parametrize('fast', [True, False])
def test_fields_inside_arrays_of_messages(tmp_path, fast):
    from maglev_ros.bags import BagWriter

    with BagWriter(tmp_path / f'arr{fast}') as bag:
        topic = bag.add_topic('/maglev/identifier/model', 'std_msgs/msg/Float64MultiArray')
        for k in range(10):
            bag.write(topic, 1000 * k, _multiarray(k))
    refs = {
        '/maglev/identifier/model': [
            parse_channel('maglev/identifier/model:layout.dim[0].size').terms[0][1],
            parse_channel('maglev/identifier/model:data[3]').terms[0][1],
        ]
    }
    with BagReader(tmp_path / f'arr{fast}') as reader:
        got = read_topics(reader, refs, fast=fast)['/maglev/identifier/model']
    np.testing.assert_array_equal(got.values[:, 0], np.full(10, 4.0))
    np.testing.assert_array_equal(got.values[:, 1], 2.0 ** -np.arange(10))
    assert got.clock == 'log'
