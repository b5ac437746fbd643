"""The identifier node's sample window and its intra-process taps (composed real-time loops).

* ``identify_from`` / ``identify_until``: the samples whose stamps fall outside
  are not given to the ARX; the estimate is that of the samples in between.
* ``intra_process`` with ``complete_on_next``: a publisher of the same
  process delivers the serialised fields in bursts of 5 samples, each burst
  followed by the one command computed from it (the real-time simulator's
  order); the identifier takes them from the taps, with no subscription on
  those topics, and pairs each burst's last sample with the command after it.
"""

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import Float64MultiArray
from waiting import wait_for

from maglev_ros import topics
from maglev_ros.nodes import intra_process
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
COMMAND_TOPIC = '/' + topics.COMMAND_TOPIC


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


def test_intra_process_taps_replace_the_subscriptions_and_pair_bursts(ctx):
    bursts, per_burst = 6, 5
    rng = np.random.default_rng(9)
    y = rng.standard_normal(bursts * per_burst + 1)  # y[k]: sample k (1-based)
    c = rng.standard_normal(bursts + 1)  # c[0]: before the run; c[b + 1]: after burst b
    publisher = rclpy.create_node('tap_publisher', context=ctx)
    taps = {
        topic: intra_process.tap(ctx, publisher.resolve_topic_name(topic))
        for topic in (FIELD_TOPIC, COMMAND_TOPIC)
    }
    for topic, tap in taps.items():
        tap.add_publisher(MagneticField if topic == FIELD_TOPIC else Float64MultiArray)
    ident = None
    try:
        ident = IdentifierNode(
            context=ctx,
            parameter_overrides=params(
                outputs=[topics.field_channel(0, 'x')],
                inputs=[topics.command_channel(0)],
                trigger=topics.field_topic(0),
                complete_on_next=True,
                intra_process=True,
                initial_covariance=P0,
                **ORDERS,
            ),
        )
        subscribed = {s.topic_name for s in ident.subscriptions}
        assert not subscribed & {FIELD_TOPIC, COMMAND_TOPIC}, subscribed
        assert all(tap.listeners == 1 for tap in taps.values())

        def command(value):
            return [serialize_message(Float64MultiArray(data=[float(value)]))]

        taps[COMMAND_TOPIC].deliver(command(c[0]))
        for b in range(bursts):
            ks = range(b * per_burst + 1, (b + 1) * per_burst + 1)
            taps[FIELD_TOPIC].deliver([serialize_message(field(k, y[k])) for k in ks])
            taps[COMMAND_TOPIC].deliver(command(c[b + 1]))
        ident.publish()  # the executor's side takes the same lock
    finally:
        if ident is not None:
            ident.destroy_node()
        for tap in taps.values():
            tap.remove_publisher()
        publisher.destroy_node()
    assert all(tap.listeners == 0 for tap in taps.values())  # disconnected
    # the last sample waits for the next stamp; the others are all identified
    n = bursts * per_burst
    assert ident.samples == n - 1 and ident.aligner.dropped == 0
    # sample k of burst b has the command before the burst, except the burst's last
    # one, which has the command computed after it (the bag converter's pairing)
    u = {k: c[(k - 1) // per_burst + (k % per_burst == 0)] for k in range(1, n)}
    expected = reference_theta((y[k], u[k]) for k in range(1, n))
    np.testing.assert_allclose(ident.identifier.arx.theta, expected, rtol=1e-9)


def test_a_long_read_of_two_stamped_topics_loses_no_sample(ctx):
    """A board driver's read after a stall: 300 samples per topic, fields then currents.

    Every stamp of the fields waits for its currents, whatever the read's length
    (the aligner keeps at least a read's stamps), and is identified.
    """
    n = 300
    rng = np.random.default_rng(6)
    y, u = rng.standard_normal(n), rng.standard_normal(n)
    publisher = rclpy.create_node('long_read_publisher', context=ctx)
    names = {'field': FIELD_TOPIC, 'currents': '/' + topics.CURRENTS_TOPIC}
    taps = {key: intra_process.tap(ctx, topic) for key, topic in names.items()}
    taps['field'].add_publisher(MagneticField)
    taps['currents'].add_publisher(JointState)
    ident = None
    try:
        ident = IdentifierNode(
            context=ctx,
            parameter_overrides=params(
                outputs=[topics.field_channel(0, 'x')],
                inputs=[topics.current_channel(0)],
                trigger=topics.field_topic(0),
                intra_process=True,
                initial_covariance=P0,
                **ORDERS,
            ),
        )
        fields = [field(k, y[k]) for k in range(n)]
        taps['field'].deliver([serialize_message(m) for m in fields])
        currents = [
            JointState(header=m.header, effort=[float(u[k])]) for k, m in enumerate(fields)
        ]
        taps['currents'].deliver([serialize_message(m) for m in currents])
    finally:
        if ident is not None:
            ident.destroy_node()
        for tap in taps.values():
            tap.remove_publisher()
        publisher.destroy_node()
    assert ident.aligner.dropped == 0 and ident.samples == n
    expected = reference_theta(zip(y, u, strict=True))
    np.testing.assert_allclose(ident.identifier.arx.theta, expected, rtol=1e-9)
