"""The identifier node's sample window, and the parameters of the removed intra-process taps.

* ``identify_from`` / ``identify_until``: the samples whose stamps fall outside
  are not given to the ARX; the estimate is that of the samples in between.
* ``intra_process`` is refused with what replaced it (the pairing of real-time
  bursts and long reads it served: ``test/bags/test_online_identification.py``).
"""

import os
import subprocess
import sys

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, MagneticField
from waiting import wait_for

from maglev_ros import topics
from maglev_ros.nodes.identifier import IdentifierNode, IdentifierParameterError
from maglev_ros.nodes.messages import split_stamp
from maglev_ros.nodes.qos import SENSOR_QOS
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.sysid.online import OnlineArx

T0_NS = 1_000_000_000  # stamp of sample 0, ns
DT_NS = 1_000_000  # ns between samples
ORDERS = dict(na=[1], nb=[1], nk=[1])
P0 = 1e6
FIELD_TOPIC = '/' + topics.field_topic(0)


def params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def field(k: int, x: float) -> MagneticField:
    msg = MagneticField()
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_stamp(T0_NS + k * DT_NS)
    msg.magnetic_field.x = float(x)
    return msg


def reference_theta(pairs) -> np.ndarray:
    """OnlineArx of the node's orders on the ``(y, u)`` pairs."""
    arx = OnlineArx(1, 1, 1, 1, 1, initial_covariance=P0)
    for y, u in pairs:
        arx.update([y], [u])
    return arx.theta


@pytest.mark.parametrize('at_run_time', [False, True], ids=['parameters', 'set-at-run-time'])
def test_identify_from_until_leave_out_the_samples_outside(ctx, at_run_time):
    n, first, last = 20, 5, 12  # samples k = 0..19; the window holds 5..12
    rng = np.random.default_rng(4)
    y, u = rng.standard_normal(n), rng.standard_normal(n)
    window = dict(
        identify_from=(T0_NS + first * DT_NS) / 1e9,  # inclusive bounds
        identify_until=(T0_NS + last * DT_NS) / 1e9,
    )
    ident = IdentifierNode(
        context=ctx,
        parameter_overrides=params(
            outputs=[topics.field_channel(0, 'x')],
            inputs=[topics.current_channel(0)],
            initial_covariance=P0,
            **(dict(identify_from=0.0, identify_until=1e-9) if at_run_time else window),
            **ORDERS,
        ),
    )
    if at_run_time:  # a lab sets the window once it knows it (both bounds in one change)
        assert ident.set_parameters_atomically(params(**window)).successful
    peer = rclpy.create_node('identifier_window_peer', context=ctx)
    field_pub = peer.create_publisher(MagneticField, topics.field_topic(0), SENSOR_QOS)
    current_pub = peer.create_publisher(JointState, topics.CURRENTS_TOPIC, SENSOR_QOS)
    spinner = Spinner(ctx, [ident, peer])
    try:
        wait_for(
            lambda: (
                field_pub.get_subscription_count() >= 1
                and current_pub.get_subscription_count() >= 1
                and all(s.get_publisher_count() >= 1 for s in ident.subscriptions)
            ),
            what='discovery',
        )
        for k in range(n):
            msg = field(k, y[k])
            joint = JointState(header=msg.header, effort=[float(u[k])])
            field_pub.publish(msg)
            current_pub.publish(joint)
        wait_for(lambda: ident.samples + ident.outside >= n, what=f'{n} samples')
    finally:
        spinner.close()
        for node in (ident, peer):
            node.destroy_node()
    assert ident.samples == last - first + 1 and ident.outside == n - ident.samples
    assert ident.aligner.dropped == 0
    window = slice(first, last + 1)
    expected = reference_theta(zip(y[window], u[window], strict=True))
    np.testing.assert_allclose(ident.identifier.arx.theta, expected, rtol=1e-9)


def test_a_window_that_ends_before_it_starts_is_refused(ctx):
    with pytest.raises(IdentifierParameterError, match='identify_until must be 0 .* >= identify'):
        IdentifierNode(
            context=ctx, parameter_overrides=params(identify_from=2.0, identify_until=1.0)
        )
    ident = IdentifierNode(context=ctx, parameter_overrides=params(identify_until=3.0))
    try:  # at run time: refused with the reason, the window unchanged
        result = ident.set_parameters_atomically(params(identify_from=4.0))
        assert not result.successful and 'identify_until must be 0' in result.reason
        assert ident.config.identify_from == 0.0 and ident.config.identify_until == 3.0
        assert ident.set_parameters_atomically(params(identify_from=4.0, identify_until=0.0))
        assert ident.config.identify_from == 4.0 and ident.config.identify_until == 0.0
        result = ident.set_parameters_atomically(params(na=[3]))  # not settable
        assert not result.successful and ident.config.na == (2,)  # the default
    finally:
        ident.destroy_node()


def test_the_removed_intra_process_is_refused_with_what_replaced_it(ctx):
    with pytest.raises(IdentifierParameterError, match='intra_process was removed: the identi'):
        IdentifierNode(context=ctx, parameter_overrides=params(intra_process=True))


def test_the_removed_parameter_ends_the_executable_with_status_2(domain):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    command = [sys.executable, '-m', 'maglev_ros.nodes.identifier', '--ros-args', '-p',
               'intra_process:=true']  # fmt: skip
    proc = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and 'intra_process was removed' in lines[0], lines


def test_stamped_commands_of_an_old_config_pair_with_their_samples(ctx, monkeypatch):
    """The contract's JointState commands read by an old config's ``data[0]``.

    A peer publishes each sample's field, then a command stamped with it
    (lockstep), on two topics: the middleware may deliver them in any order
    across the topics, and the pairing is by stamp: the estimate is that of
    ``(y[k], c[k])``.
    """
    monkeypatch.setitem(topics.MESSAGE_TYPES, topics.COMMAND_TOPIC, 'sensor_msgs/msg/JointState')
    n = 40
    rng = np.random.default_rng(8)
    y, c = rng.standard_normal(n), rng.standard_normal(n)
    ident = IdentifierNode(
        context=ctx,
        parameter_overrides=params(
            outputs=[topics.field_channel(0, 'x')],
            inputs=[f'{topics.COMMAND_TOPIC}:data[0]'],  # the spelling of older configs
            initial_covariance=P0,
            **ORDERS,
        ),
    )
    peer = rclpy.create_node('identifier_command_peer', context=ctx)
    field_pub = peer.create_publisher(MagneticField, topics.field_topic(0), SENSOR_QOS)
    command_pub = peer.create_publisher(JointState, topics.COMMAND_TOPIC, SENSOR_QOS)
    spinner = Spinner(ctx, [ident, peer])
    try:
        wait_for(
            lambda: (
                field_pub.get_subscription_count() >= 1
                and command_pub.get_subscription_count() >= 1
                and all(s.get_publisher_count() >= 1 for s in ident.subscriptions)
            ),
            what='discovery',
        )
        for k in range(n):
            msg = field(k, y[k])
            field_pub.publish(msg)
            command_pub.publish(JointState(header=msg.header, effort=[float(c[k]), 0.0, 0, 0]))
        wait_for(lambda: ident.samples >= n, what=f'{n} samples')
    finally:
        spinner.close()
        for node in (ident, peer):
            node.destroy_node()
    assert ident.samples == n and ident.aligner.dropped == 0
    expected = reference_theta(zip(y, c, strict=True))
    np.testing.assert_allclose(ident.identifier.arx.theta, expected, rtol=1e-9)
