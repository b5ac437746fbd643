"""The identifier node on the levitating magnet's samples across a reference step.

Issue 10, "Identifier convergence": with forgetting factor 1 the node's
coefficients are the batch ARX of the same samples (1e-6 relative); with
forgetting 0.999 they follow a change of operating point (a reference step).

The samples come from the ROS-free :class:`~maglev_ros.control.ClosedLoop`,
which steps to the same numbers as the lockstep graph of the simulator,
estimator and controller nodes (``test_closed_loop_nodes.py``), in about
under 2 s instead of minutes: the issue's board (V2, sensor noise 1e-4 T,
quantisation, coil electrics), the magnet held 0.4 mm off centre in x, a PRBS
of 0.1 A on ``ux`` added to the command, and at 0.8 s the reference steps to the
centre. A peer publishes each sample as the simulator does (sensor 0's
MagneticField and the JointState of the coil currents, one stamp) to two
identifier nodes, ARX 2 2 1 of ``Bx`` (mT) against ``ux``: forgetting 1 and
forgetting 0.999 (a memory of ~1000 samples, 0.2 s).

What must hold (the data are deterministic: a fixed seed):

* the tracking node is the exponentially weighted batch ARX of the samples so
  far (weights 0.999^age), before the step and at the end; so it is near the
  batch ARX of the pre-step samples before the step, and at the end near the
  batch ARX of the settled post-step samples (from 0.2 s after the step), far
  from the pre-step model;
* the node with forgetting 1 equals the batch ARX of all the samples (the
  pooled estimate) within 1e-6 relative, and so stays far from the
  post-step model.
"""

import numpy as np
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import Float64MultiArray
from waiting import wait_for

from maglev_ros import topics
from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.nodes.identifier import IdentifierNode
from maglev_ros.nodes.messages import split_stamp
from maglev_ros.nodes.qos import SENSOR_QOS
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.sysid import IdData, arx

RATE = 5000.0
N = 8_000  # samples: 1.6 s
STEP = 4_000  # the reference step, sample (0.8 s)
SETTLE = 1_000  # samples after the step before the new operating point counts (0.2 s)
OFFSET = 4e-4  # m, x of the first operating point
SEED = 3
CHUNK = 200  # samples published before waiting for the nodes (the QoS keeps 1000)
ORDERS = dict(na=[2], nb=[2], nk=[1])
OUTPUT = f'Bx_mT=1000*{topics.field_channel(0, "x")}'
INPUT = f'ux=0.5*{topics.current_channel(0)}-0.5*{topics.current_channel(1)}'


def _relative(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _closed_loop_run():
    """Readings (N, 3k) T and coil currents (N, 4) A of the levitating magnet."""
    loop = make_closed_loop('maggy_v2', noise=1e-4, quantization=0.098e-3, seed=SEED)
    z = loop.z_eq
    rng = np.random.default_rng(SEED)
    prbs = 0.1 * np.repeat(rng.choice([-1.0, 1.0], N // 4 + 1), 4)[:N]  # A, 4-sample hold
    excitation = np.zeros((N, 4))
    excitation[:, 0], excitation[:, 1] = prbs, -prbs  # ux = 0.5 (i0 - i1)
    result = loop.run(
        N / RATE,
        x0=[OFFSET, 0.0, z] + [0.0] * 9,
        reference=lambda t: [OFFSET, 0.0, z] if t < STEP / RATE else [0.0, 0.0, z],
        excitation=excitation,
    )
    assert not result.crashed, result.reason
    x = result.x[:, 0]
    assert abs(np.mean(x[STEP - SETTLE : STEP]) - OFFSET) < 1e-4  # held off centre
    assert abs(np.mean(x[STEP + SETTLE :])) < 1e-4  # then at the centre (0.1 mm)
    return result.readings, result.currents


def _identifier(ctx, namespace, forgetting):
    return IdentifierNode(
        context=ctx,
        namespace=namespace,
        parameter_overrides=[
            Parameter('outputs', value=[OUTPUT]),
            Parameter('inputs', value=[INPUT]),
            Parameter('forgetting', value=forgetting),
            Parameter('initial_covariance', value=1e8),  # a weak prior: batch ARX
            Parameter('publish_rate', value=20.0),
            *(Parameter(k, value=v) for k, v in ORDERS.items()),
        ],
    )


def test_forgetting_follows_a_reference_step_and_one_stays_pooled(ctx):
    readings, currents = _closed_loop_run()
    y = 1000 * readings[:, 0:1]  # Bx of sensor 0, mT (the channel's scale)
    u = 0.5 * currents[:, 0:1] - 0.5 * currents[:, 1:2]

    def batch(start, stop):
        return arx(IdData(y[start:stop], u[start:stop], 1 / RATE), 2, 2, 1).theta

    def weighted(stop, forgetting=0.999):
        """ARX 2 2 1 of samples 0 .. stop-1, each residual weighted forgetting^age."""
        k = np.arange(2, stop)
        phi = np.column_stack([-y[k - 1, 0], -y[k - 2, 0], u[k - 1, 0], u[k - 2, 0]])
        w = forgetting ** (stop - 1 - k)
        return np.linalg.solve(phi.T @ (w[:, None] * phi), phi.T @ (w * y[k, 0]))

    pre, post, pooled = batch(0, STEP), batch(STEP + SETTLE, N), batch(0, N)
    assert _relative(weighted(N, 1.0), pooled) < 1e-9  # the same regression as the batch
    assert _relative(pre, post) > 0.3, (pre, post)  # two operating points, two models

    namespaces = ('tracking', 'pooled')
    tracking = _identifier(ctx, namespaces[0], 0.999)
    frozen = _identifier(ctx, namespaces[1], 1.0)
    peer = rclpy.create_node('identifier_step_peer', context=ctx)
    field_pubs = [
        peer.create_publisher(MagneticField, f'/{ns}/{topics.field_topic(0)}', SENSOR_QOS)
        for ns in namespaces
    ]
    current_pubs = [
        peer.create_publisher(JointState, f'/{ns}/{topics.CURRENTS_TOPIC}', SENSOR_QOS)
        for ns in namespaces
    ]
    models = {ns: [] for ns in namespaces}
    for ns in namespaces:
        peer.create_subscription(
            Float64MultiArray,
            f'/{ns}/{topics.IDENTIFIER_MODEL_TOPIC}',
            lambda m, ns=ns: models[ns].append(np.array(m.data)),
            10,
        )
    nodes = (tracking, frozen)
    spinner = Spinner(ctx, [tracking, frozen, peer])

    def feed(start, stop):
        for first in range(start, stop, CHUNK):
            last = min(first + CHUNK, stop)
            for k in range(first, last):
                sec, nanosec = split_stamp(1_000_000_000 + k * 200_000)
                field = MagneticField()
                field.header.stamp.sec, field.header.stamp.nanosec = sec, nanosec
                field.magnetic_field.x, field.magnetic_field.y, field.magnetic_field.z = (
                    float(v) for v in readings[k, 0:3]
                )
                joint = JointState()
                joint.header.stamp.sec, joint.header.stamp.nanosec = sec, nanosec
                joint.effort = [float(v) for v in currents[k]]
                for pub in field_pubs:
                    pub.publish(field)
                for pub in current_pubs:  # the trigger topic last, as the simulator
                    pub.publish(joint)
            wait_for(
                lambda last=last: all(n.samples >= last for n in nodes),
                timeout=60.0,
                what=f'{last} samples in both identifiers',
            )

    def fresh_models():
        """The next model each node publishes (after the samples fed so far)."""
        counts = {ns: len(models[ns]) for ns in namespaces}
        wait_for(
            lambda: all(len(models[ns]) > counts[ns] + 1 for ns in namespaces),
            timeout=60.0,
            what='models published after the samples',
        )
        return {ns: models[ns][-1] for ns in namespaces}

    try:
        wait_for(
            lambda: (
                all(p.get_subscription_count() >= 1 for p in field_pubs + current_pubs)
                and all(  # both ends matched: the readers know the writers too
                    sub.get_publisher_count() >= 1 for n in nodes for sub in n.subscriptions
                )
            ),
            timeout=60.0,
            what='discovery',
        )
        feed(0, STEP)
        before = fresh_models()
        feed(STEP, N)
        after = fresh_models()
    finally:
        spinner.close()
        for node in (tracking, frozen, peer):
            node.destroy_node()
    assert tracking.samples == N and frozen.samples == N
    assert tracking.aligner.dropped == 0 and frozen.aligner.dropped == 0
    # forgetting 0.999 is the exponentially weighted batch ARX of the samples so far
    # (weights 0.999^age: a memory of ~1000 samples), so it follows the operating
    # point: nearer the post-step model than the pre-step one after the step
    assert _relative(before['tracking'], weighted(STEP)) < 1e-4, (before['tracking'], pre)
    assert _relative(after['tracking'], weighted(N)) < 1e-4, (after['tracking'], post)
    assert _relative(before['tracking'], pre) < 0.2, (before['tracking'], pre)
    assert _relative(after['tracking'], post) < 0.2, (after['tracking'], post)
    assert _relative(after['tracking'], pre) > 0.3, (after['tracking'], pre)
    # forgetting 1: the batch ARX of all the samples, which the step does not move to
    # the new operating point
    assert _relative(after['pooled'], pooled) < 1e-6, (after['pooled'], pooled)
    assert _relative(before['pooled'], pre) < 1e-6, (before['pooled'], pre)
    assert _relative(after['pooled'], post) > 0.3, (after['pooled'], post)
