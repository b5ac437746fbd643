"""The simulator's samples as CDR messages, without ROS: order, contents, /clock per burst."""

import numpy as np
import pytest

from maglev_ros.cdr.typestore import jazzy_typestore
from maglev_ros.physics import Simulator
from maglev_ros.physics.kernels import odometry_values
from maglev_ros.physics.sample_encoder import SampleEncoder
from maglev_ros.physics.session import SampleBatch, SimulationSession

RATE = 5000.0
FREE = [0.001, 0.0, 0.0365] + [0.0] * 9  # a falling magnet: its state changes every sample


def _batch(v2, samples=5, burst=5):
    sim = Simulator(v2, RATE, magnet='free', x0=FREE)
    session = SimulationSession(sim, 'realtime', pace_period=burst / RATE, now=0.0)
    session.start(now=0.0)
    assert session.pace(0.0)[0] is None  # pacing starts
    batch, _ = session.pace(samples / RATE + 1e-9)
    assert len(batch) == samples
    return batch


def _decode(message, kind):
    return jazzy_typestore().deserialize_cdr(message, kind)


def test_messages_per_sample_in_topic_order_with_the_batch_values(v2):
    batch = _batch(v2)
    encoder = SampleEncoder([1, 2], state=True, clock='sample')
    assert encoder.topics == (
        '/clock',
        'maglev/sensor_1/field',
        'maglev/sensor_2/field',
        'maglev/state/true',
        'maglev/currents',
    )
    messages = encoder.sample_messages(batch)
    assert len(messages) == len(batch) * 5
    assert encoder.clock_messages(batch) == []  # /clock goes with every sample
    for i in range(len(batch)):
        clock, f1, f2, odom, currents = messages[5 * i : 5 * i + 5]
        stamp = int(batch.stamps_ns[i])
        t = _decode(clock, 'rosgraph_msgs/msg/Clock').clock
        assert t.sec * 10**9 + t.nanosec == stamp
        for k, raw in ((1, f1), (2, f2)):
            field = _decode(raw, 'sensor_msgs/msg/MagneticField')
            assert field.header.frame_id == f'maglev_sensor_{k}'
            got = [field.magnetic_field.x, field.magnetic_field.y, field.magnetic_field.z]
            assert got == batch.readings[i, 3 * k : 3 * k + 3].tolist()
        o = _decode(odom, 'nav_msgs/msg/Odometry')
        values = odometry_values(batch.states[i])
        p, q = o.pose.pose.position, o.pose.pose.orientation
        assert [p.x, p.y, p.z, q.x, q.y, q.z, q.w] == pytest.approx(values[:7], abs=0)
        j = _decode(currents, 'sensor_msgs/msg/JointState')
        assert list(j.effort) == batch.currents[i].tolist()
        assert j.header.stamp.sec * 10**9 + j.header.stamp.nanosec == stamp


def test_clock_once_per_burst_and_no_state(v2):
    batch = _batch(v2, samples=10, burst=4)  # indices 1 .. 10: bursts start at 4 and 8
    encoder = SampleEncoder([0], state=False, clock='burst', burst=4)
    assert encoder.topics == ('maglev/sensor_0/field', 'maglev/currents')
    ticks = [_decode(m, 'rosgraph_msgs/msg/Clock').clock for m in encoder.clock_messages(batch)]
    expected = batch.stamps_ns[batch.indices % 4 == 0].tolist()
    assert [t.sec * 10**9 + t.nanosec for t in ticks] == expected and len(expected) == 2
    assert len(encoder.sample_messages(batch)) == 2 * len(batch)
    assert SampleEncoder([0], state=False, clock='none').clock_messages(batch) == []


def test_unknown_clock_mode_is_refused():
    with pytest.raises(ValueError, match="clock must be one of none, sample, burst, got 'x'"):
        SampleEncoder([0], state=False, clock='x')


def test_fixed_magnet_odometry_is_computed_once_and_stays_exact(v2):
    sim = Simulator(v2, RATE, magnet='fixed')
    session = SimulationSession(sim, 'lockstep', now=0.0)
    encoder = SampleEncoder([0], state=True, clock='none')
    first = encoder.sample_messages(session.start(now=0.0))
    later = encoder.sample_messages(session.command(np.zeros(4), now=0.0))
    a, b = (_decode(m[1], 'nav_msgs/msg/Odometry').pose.pose for m in (first, later))
    assert (a.position.z, a.orientation.w) == (b.position.z, b.orientation.w)
    assert a.position.z == odometry_values(sim.state)[2]


@pytest.mark.parametrize(
    'active',
    [
        (True, False, True, False, True),  # /clock, sensor 2, currents
        (False, False, False, True, False),  # the true state only
        (False, True, True, False, True),
        (False,) * 5,
    ],
)
def test_topics_without_subscribers_are_not_serialised(v2, active):
    batch = _batch(v2)
    encoder = SampleEncoder([1, 2], state=True, clock='sample')
    full = encoder.sample_messages(batch)
    some = encoder.sample_messages(batch, active)
    k = sum(active)
    assert len(some) == k * len(batch)
    for i in range(len(batch)):
        wanted = [m for m, a in zip(full[5 * i : 5 * i + 5], active, strict=True) if a]
        assert some[k * i : k * i + k] == wanted


def test_publish_hands_each_message_to_its_topic_clock_first(v2):
    batch = _batch(v2, samples=10, burst=5)  # indices 1 .. 10: a burst starts at 5 and 10
    encoder = SampleEncoder([1, 2], state=True, clock='burst', burst=5)
    sent = []

    def to(topic):
        return lambda message: sent.append((topic, message))

    calls = [to(t) if t != 'maglev/sensor_1/field' else None for t in encoder.topics]
    assert encoder.publish(batch, calls, to('/clock')) == 3 * len(batch)
    clocks = encoder.clock_messages(batch)
    assert sent[:2] == [('/clock', m) for m in clocks]  # /clock first
    active = [c is not None for c in calls]
    expected = encoder.sample_messages(batch, active)
    assert [m for _, m in sent[2:]] == expected  # sample after sample
    assert [t for t, _ in sent[2:5]] == ['maglev/sensor_2/field', 'maglev/state/true',
                                         'maglev/currents']  # fmt: skip
    sent.clear()
    assert encoder.publish(batch, [None] * 4, to('/clock')) == 0  # nobody reads the samples
    assert [t for t, _ in sent] == ['/clock', '/clock']
    crash = SampleBatch(
        np.empty(0, np.int64),
        np.empty(0, np.int64),
        *(np.empty((0, n)) for n in (9, 12, 4)),
        crashed=True,
    )
    sent.clear()
    assert encoder.publish(crash, calls, to('/clock')) == 0 and sent == []  # a crash alone
