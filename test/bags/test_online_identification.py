"""The identifier node's core: channels, sample completeness, bursts, window, report.

Messages are rosbags dataclasses (no rclpy). The commands are built in the
type the topic contract gives the command topic (JointState, or the older
Float64MultiArray); the channel specs say ``data[i]`` either way, the spelling
of older configurations.
"""

import numpy as np
import pytest

from maglev_ros import topics
from maglev_ros.bags import BagError
from maglev_ros.bags.online_identification import (
    OnlineIdentification,
    OnlineIdentificationConfig,
    message_type_of,
)
from maglev_ros.bags.typestore import jazzy_typestore
from maglev_ros.sysid.online import OnlineArx

T = jazzy_typestore().types
T0_NS, DT_NS, P0 = 1_000_000_000, 1_000_000, 1e6
FIELD, CURRENTS, COMMAND = ('/' + t for t in (topics.field_topic(0), topics.CURRENTS_TOPIC,
                                              topics.COMMAND_TOPIC))  # fmt: skip


def config(**changes):
    values = dict(
        outputs=(topics.field_channel(0, 'x'),),
        inputs=(topics.current_channel(0),),
        na=(1,),
        nb=(1,),
        nk=(1,),
        forgetting=1.0,
        initial_covariance=P0,
        window=0,
        fit_window=100,
        wait_for_history=True,
        trigger='',
        publish_rate=10.0,
    )
    return OnlineIdentificationConfig(**(values | changes))


def header(k):
    sec, nanosec = divmod(T0_NS + k * DT_NS, 1_000_000_000)
    stamp = T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)
    return T['std_msgs/msg/Header'](stamp=stamp, frame_id='maglev')


def field(k, x):
    vec = T['geometry_msgs/msg/Vector3'](x=float(x), y=0.0, z=0.0)
    return T['sensor_msgs/msg/MagneticField'](
        header=header(k), magnetic_field=vec, magnetic_field_covariance=np.zeros(9)
    )


def joint_state(k, effort):
    return T['sensor_msgs/msg/JointState'](
        header=header(k),
        name=list(topics.COIL_NAMES),
        position=np.zeros(0),
        velocity=np.zeros(0),
        effort=np.asarray(effort, dtype=float),
    )


def command(k, value):
    """A command of the contract's type answering sample ``k``."""
    values = [float(value), 0.0, 0.0, 0.0]
    if message_type_of(COMMAND) == 'sensor_msgs/msg/JointState':
        return joint_state(k, values)
    layout = T['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0)
    return T['std_msgs/msg/Float64MultiArray'](layout=layout, data=np.asarray(values))


def reference_theta(pairs):
    arx = OnlineArx(1, 1, 1, 1, 1, initial_covariance=P0)
    for y, u in pairs:
        arx.update([y], [u])
    return arx.theta


@pytest.mark.parametrize(
    'command_type', ['sensor_msgs/msg/JointState', 'std_msgs/msg/Float64MultiArray']
)
def test_complete_on_next_pairs_each_burst_with_the_command_after_it(monkeypatch, command_type):
    """The real-time simulator's order: 5 samples, then the command computed from them.

    Either command type of the contract, read by the old spelling ``data[0]``.
    """
    monkeypatch.setitem(topics.MESSAGE_TYPES, topics.COMMAND_TOPIC, command_type)
    bursts, per_burst = 6, 5
    rng = np.random.default_rng(9)
    y = rng.standard_normal(bursts * per_burst + 1)  # y[k]: sample k (1-based)
    c = rng.standard_normal(bursts + 1)  # c[0]: before the run; c[b + 1]: after burst b
    core = OnlineIdentification(
        config(inputs=(topics.command_channel(0),), trigger=FIELD, complete_on_next=True)
    )
    assert core.stamped == {FIELD}  # the command is held, whatever its type
    core.add(COMMAND, command(0, c[0]))
    for b in range(bursts):
        ks = range(b * per_burst + 1, (b + 1) * per_burst + 1)
        for k in ks:
            core.add(FIELD, field(k, y[k]))
        core.add(COMMAND, command(ks[-1], c[b + 1]))
    n = bursts * per_burst
    assert core.samples == n - 1 and core.aligner.dropped == 0  # the last waits
    u = {k: c[(k - 1) // per_burst + (k % per_burst == 0)] for k in range(1, n)}
    expected = reference_theta((y[k], u[k]) for k in range(1, n))
    np.testing.assert_allclose(core.identifier.arx.theta, expected, rtol=1e-9)


def test_a_long_read_of_two_stamped_topics_loses_no_sample():
    """A board driver's read after a stall: 300 fields, then their 300 currents."""
    n = 300
    rng = np.random.default_rng(6)
    y, u = rng.standard_normal(n), rng.standard_normal(n)
    core = OnlineIdentification(config(trigger=FIELD))
    for k in range(n):
        core.add(FIELD, field(k, y[k]))
    for k in range(n):
        core.add(CURRENTS, joint_state(k, [u[k], 0, 0, 0]))
    assert core.aligner.dropped == 0 and core.samples == n
    np.testing.assert_allclose(
        core.identifier.arx.theta, reference_theta(zip(y, u, strict=True)), rtol=1e-9
    )


def test_the_window_leaves_out_samples_and_reset_starts_over():
    n, first, last = 20, 5, 12
    rng = np.random.default_rng(4)
    y, u = rng.standard_normal(n), rng.standard_normal(n)
    core = OnlineIdentification(config())
    report = core.report()
    assert report.layout is None and report.message == 'waiting for complete samples'
    core.set_window(T0_NS + first * DT_NS, T0_NS + last * DT_NS)
    for k in range(n):
        core.add(FIELD, field(k, y[k]))
        core.add(CURRENTS, joint_state(k, [u[k], 0, 0, 0]))
    assert core.samples == last - first + 1 and core.outside == n - core.samples
    window = slice(first, last + 1)
    expected = reference_theta(zip(y[window], u[window], strict=True))
    np.testing.assert_allclose(core.identifier.arx.theta, expected, rtol=1e-9)
    report = core.report()
    assert (report.level, report.message) == (0, 'estimating')
    assert report.values['samples'] == core.samples
    assert report.values['samples outside the window'] == n - core.samples
    assert report.outputs == (topics.field_channel(0, 'x'),)
    assert report.layout.labels[0] == 'theta'
    assert core.reset() == last - first + 1 and core.samples == 0
    assert core.describe().startswith('recursive ARX')


def test_bad_channels_and_orders_are_refused():
    with pytest.raises(BagError, match="channel topic '/maglev/elsewhere' is not in the topic"):
        OnlineIdentification(config(inputs=('maglev/elsewhere:data[0]',)))
    with pytest.raises(BagError, match=r'nb must have 1 or 1\*2 = 2 values, got \[1, 1, 1\]'):
        OnlineIdentification(
            config(inputs=(topics.current_channel(0), topics.current_channel(1)), nb=(1, 1, 1))
        )
    with pytest.raises(BagError, match="trigger topic '/maglev/currents/command' is not read"):
        OnlineIdentification(config(trigger=COMMAND))
    assert message_type_of('maglev/sensor_7/field') == 'sensor_msgs/msg/MagneticField'


def _shuffled_across_topics(messages, seed):
    """The messages with each topic's order kept and the order across topics random."""
    rng = np.random.default_rng(seed)
    queues = {}
    for topic, message in messages:
        queues.setdefault(topic, []).append((topic, message))
    out = []
    while any(queues.values()):
        topic = rng.choice(sorted(t for t, q in queues.items() if q))
        out.append(queues[topic].pop(0))
    return out


@pytest.mark.parametrize('burst', [1, 5], ids=['lockstep', 'bursts'])
def test_stamped_commands_pair_by_stamp_whatever_the_arrival_order(monkeypatch, burst):
    """JointState commands: sample k's input is the newest command stamped <= k.

    The default trigger (the first input's topic, the command's) gives way to the
    sample's own topics; no ``complete_on_next`` is needed, and no sample waits for
    a later stamp than its command's.
    """
    monkeypatch.setitem(topics.MESSAGE_TYPES, topics.COMMAND_TOPIC, 'sensor_msgs/msg/JointState')
    n = 60
    rng = np.random.default_rng(12)
    y = rng.standard_normal(n)
    c = {k: rng.standard_normal() for k in range(burst - 1, n, burst)}  # answers k
    messages = []
    for k in range(n):
        messages += [(FIELD, field(k, y[k])), (CURRENTS, joint_state(k, [0, 0, 0, 0]))]
        if k in c:
            messages.append((COMMAND, command(k, c[k])))
    expected_u = [c[max(j for j in c if j <= k)] for k in range(burst - 1, n)]
    expected = reference_theta(zip(y[burst - 1 :], expected_u, strict=True))
    for seed in range(5):
        core = OnlineIdentification(
            config(inputs=(topics.command_channel(0),), outputs=(topics.field_channel(0, 'x'),))
        )
        assert core.identifier.sampler.trigger == FIELD  # the sample's own topic
        assert core.aligner.held_stamped == (COMMAND,)
        for topic, message in _shuffled_across_topics(messages, seed):
            core.add(topic, message)
        # samples before the first command have no input yet: counted as waiting
        assert core.samples == n - (burst - 1) and core.aligner.dropped == 0
        np.testing.assert_allclose(core.identifier.arx.theta, expected, rtol=1e-9)


def test_channels_of_commands_alone_take_every_command_as_a_sample(monkeypatch):
    """No sample topic to pair with: each command (the trigger) is a sample, none waits."""
    monkeypatch.setitem(topics.MESSAGE_TYPES, topics.COMMAND_TOPIC, 'sensor_msgs/msg/JointState')
    core = OnlineIdentification(
        config(outputs=(topics.command_channel(1),), inputs=(topics.command_channel(0),))
    )
    assert core.stamped == frozenset() and core.aligner.held_stamped == ()
    for k in range(10):
        core.add(COMMAND, joint_state(k, [k, 2 * k, 0, 0]))
    assert core.samples == 10
