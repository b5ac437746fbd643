"""Sample streams in a thread of their own, and the estimate's CDR encoder."""

from __future__ import annotations

import numpy as np
import pytest
from waiting import wait_for


def _publish_samples(node, n):
    """Publish n samples: a MagneticField on 'f0' and 'f1' and a JointState on 'c' each."""
    from sensor_msgs.msg import JointState, MagneticField

    from maglev_ros.nodes.qos import SENSOR_QOS

    pubs = [node.create_publisher(MagneticField, t, SENSOR_QOS) for t in ('f0', 'f1')]
    cur = node.create_publisher(JointState, 'c', SENSOR_QOS)
    wait_for(lambda: all(p.get_subscription_count() for p in [*pubs, cur]), 10.0, 'matching')
    for k in range(n):
        for j, pub in enumerate(pubs):
            msg = MagneticField()
            msg.header.stamp.nanosec = k
            msg.magnetic_field.x = float(j)
            pub.publish(msg)
        msg = JointState()
        msg.header.stamp.nanosec = k
        cur.publish(msg)


@pytest.mark.parametrize('own_thread', [True, False])
def test_streams_take_every_message_a_sample_at_a_time(ctx, own_thread):
    import rclpy
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState, MagneticField

    from maglev_ros.nodes.qos import SENSOR_QOS
    from maglev_ros.nodes.runtime import Spinner
    from maglev_ros.nodes.sample_streams import SampleStreams, Stream, open_streams

    node = rclpy.create_node('streams_test', context=ctx)
    source = rclpy.create_node('streams_source', context=ctx)
    got: list[tuple[str, int]] = []

    def keep(name, msg_type):
        return lambda raw: got.append(
            (name, deserialize_message(raw, msg_type).header.stamp.nanosec)
        )

    streams = open_streams(
        node,
        [
            Stream(MagneticField, 'f0', keep('f0', MagneticField)),
            Stream(MagneticField, 'f1', keep('f1', MagneticField)),
            Stream(JointState, 'c', keep('c', JointState)),
        ],
        SENSOR_QOS,
        own_thread=own_thread,
    )
    assert isinstance(streams, SampleStreams) if own_thread else streams is None
    spinner = Spinner(ctx, [node] if streams is None else [])
    try:
        _publish_samples(source, 300)
        wait_for(lambda: len(got) == 900, 20.0, 'every message')
    finally:
        spinner.close()
        if streams is not None:
            streams.close()
            assert not streams._thread.is_alive()
    for name in ('f0', 'f1', 'c'):  # each topic in order, none lost
        assert [k for n, k in got if n == name] == list(range(300))
    if own_thread:  # round robin: a sample's currents come after its fields
        assert streams.taken == 900 and streams.wake_ups <= 900
        for i, (name, k) in enumerate(got):
            if name == 'c':
                assert ('f0', k) in got[:i] and ('f1', k) in got[:i]
    node.destroy_node()
    source.destroy_node()


def test_streams_end_with_their_context(domain):
    import rclpy
    from rclpy.context import Context
    from sensor_msgs.msg import MagneticField

    from maglev_ros.nodes.qos import SENSOR_QOS
    from maglev_ros.nodes.sample_streams import SampleStreams, Stream

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('streams_end', context=context)
    streams = SampleStreams(node, [Stream(MagneticField, 'f0', lambda raw: None)], SENSOR_QOS)
    rclpy.try_shutdown(context=context)
    streams._thread.join(timeout=2.0)
    assert not streams._thread.is_alive()


def test_estimate_encoder_bytes_are_the_estimate_message():
    from nav_msgs.msg import Odometry
    from rclpy.serialization import deserialize_message

    from maglev_ros.nodes.state_messages import EstimateEncoder, estimate_message

    rng = np.random.default_rng(3)
    encoder = EstimateEncoder()
    for t_ns in (0, 123_456_789_012, 5 * 10**9 + 200_000):
        x = 0.05 * rng.standard_normal(12)
        a = rng.standard_normal((12, 12))
        cov = a @ a.T
        got = deserialize_message(encoder.encode(t_ns, x, cov), Odometry)
        want = estimate_message(t_ns, x, cov)
        assert got.header == want.header and got.child_frame_id == want.child_frame_id
        assert got.pose.pose == want.pose.pose
        np.testing.assert_array_equal(got.pose.covariance, want.pose.covariance)
        np.testing.assert_array_equal(got.twist.covariance, want.twist.covariance)
        np.testing.assert_allclose(
            [got.twist.twist.linear.x, got.twist.twist.linear.y, got.twist.twist.linear.z],
            [want.twist.twist.linear.x, want.twist.twist.linear.y, want.twist.twist.linear.z],
            rtol=1e-15,
            atol=1e-18,
        )
        assert got.twist.twist.angular == want.twist.twist.angular
