"""RawFieldReader against rosbags' own serialiser: stamps and fields, layout changes."""

import numpy as np

from maglev_ros.cdr import CURRENT_VALUES, FIELD_VALUES, ODOMETRY_VALUES, default_message
from maglev_ros.cdr.reader import RawFieldReader
from maglev_ros.cdr.typestore import jazzy_typestore

STORE = jazzy_typestore()


def _raw(msg, msgtype):
    return bytes(STORE.serialize_cdr(msg, msgtype))


def _field(frame, sec, nanosec, xyz):
    msg = default_message('sensor_msgs/msg/MagneticField')
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = xyz
    msg.magnetic_field_covariance = np.arange(9.0)
    return _raw(msg, 'sensor_msgs/msg/MagneticField')


def test_reads_stamp_and_field_and_follows_a_new_layout():
    reader = RawFieldReader('sensor_msgs/msg/MagneticField', FIELD_VALUES)
    assert reader.read(_field('maglev_sensor_0', 3, 200_000, (1e-5, -2e-6, 0.02))) == (
        3_000_200_000,
        (1e-5, -2e-6, 0.02),
    )
    assert reader.read(_field('maglev_sensor_0', 3, 400_000, (2.0, 3.0, 4.0))) == (
        3_000_400_000,
        (2.0, 3.0, 4.0),
    )
    assert reader.layouts == 1  # the same layout: no walk
    # another frame id of the same length moves nothing; a longer one moves the fields
    assert reader.read(_field('maglev_sensor_1', 0, 5, (7.0, 8.0, 9.0))) == (5, (7.0, 8.0, 9.0))
    assert reader.read(_field('a_much_longer_frame_id', 1, 0, (1.0, 2.0, 3.0))) == (
        1_000_000_000,
        (1.0, 2.0, 3.0),
    )
    assert reader.layouts == 2


def test_reads_joint_efforts_and_refuses_too_few():
    reader = RawFieldReader('sensor_msgs/msg/JointState', CURRENT_VALUES)
    msg = default_message('sensor_msgs/msg/JointState')
    msg.name = ['x+', 'x-', 'y+', 'y-']
    msg.position = np.zeros(4)
    msg.effort = np.array([0.1, -0.2, 0.3, -0.4])
    msg.header.stamp.nanosec = 7
    assert reader.read(_raw(msg, 'sensor_msgs/msg/JointState')) == (7, (0.1, -0.2, 0.3, -0.4))
    msg.effort = np.array([0.1, -0.2, 0.3])  # a fourth coil is missing
    assert reader.read(_raw(msg, 'sensor_msgs/msg/JointState')) is None


def test_reads_odometry_and_refuses_big_endian():
    reader = RawFieldReader('nav_msgs/msg/Odometry', ODOMETRY_VALUES)
    msg = default_message('nav_msgs/msg/Odometry')
    msg.header.frame_id, msg.child_frame_id = 'maglev_base', 'maglev_magnet'
    values = np.linspace(-1.0, 1.0, 13)
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    v, w = msg.twist.twist.linear, msg.twist.twist.angular
    p.x, p.y, p.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z, w.x, w.y, w.z = values
    msg.pose.covariance = np.arange(36.0)
    raw = _raw(msg, 'nav_msgs/msg/Odometry')
    stamp, got = reader.read(raw)
    assert stamp == 0 and got == tuple(values)
    big = bytes(STORE.serialize_cdr(msg, 'nav_msgs/msg/Odometry', little_endian=False))
    assert reader.read(big) is None
