"""The session's bag: the recorder node's topics of a lab bag, each message at its sample's stamp.

A bag recorded by the closed-loop lab identifies as recorded: ``maglev-sysid``'s
loader takes every sample, with no gap in the commands and no repeated stamp.
"""

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from maglev_ros import topics
from maglev_ros.bags import BagReader, load_bag_dataset, read_bag
from maglev_ros.control.excitation import CommandExcitation
from maglev_ros.loop import BagRecorder, LabSettings, build_lab_loop, lab_plan, run_session
from maglev_ros.loop.lab import simulator_metadata

N = 400


def _record(path, **more):
    e = CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs', seed=5, length=N)
    s = LabSettings(samples=N, settle=0.05, seed=5, excitation=e, **more)
    recorder = BagRecorder(path, (0, 1), metadata=simulator_metadata(s), clock=not s.realtime)
    recorded = []

    def both(w):
        recorded.append(w)
        recorder(w)

    try:
        run_session(build_lab_loop(s), lab_plan(s), {'recorder': both})
    finally:
        recorder.close()
    return recorded, recorder


def _log_times(path):
    times = {}
    with Reader(path) as reader:
        for connection, t, _ in reader.messages():
            times.setdefault(connection.topic, []).append(t)
    return {k: np.array(v) for k, v in times.items()}


def test_lockstep_bag_holds_every_recorded_sample_on_every_topic_at_its_stamp(tmp_path):
    bag = tmp_path / 'bag'
    recorded, recorder = _record(bag)
    stamps = np.array([w.sample.stamp_ns for w in recorded])
    times = _log_times(bag)
    expected = [topics.field_topic(0), topics.field_topic(1), topics.CURRENTS_TOPIC,
                topics.COMMAND_TOPIC, topics.EXCITATION_TOPIC, topics.TRUE_STATE_TOPIC,
                topics.CLOCK_TOPIC]  # fmt: skip
    assert sorted(times) == sorted('/' + t.lstrip('/') for t in expected)
    for topic, t in times.items():
        np.testing.assert_array_equal(t, stamps, err_msg=topic)
    channels = [topics.field_channel(1, 'z')]
    inputs = [topics.command_channel(k) for k in range(4)]
    inputs += [topics.excitation_channel(k) for k in range(4)]
    data = read_bag(bag, channels, inputs).data
    np.testing.assert_array_equal(data.u[:, :4], [w.command for w in recorded])
    np.testing.assert_array_equal(data.u[:, 4:], [w.excitation for w in recorded])
    np.testing.assert_array_equal(data.y[:, 0], [w.sample.reading[5] for w in recorded])
    with BagReader(bag) as reader:
        meta = reader.metadata
    assert meta['maglev_simulator.magnet'] == 'free' and meta['maglev_simulator.seed'] == 5
    assert meta['recorder.log_clock'] == 'stamp'
    assert recorder.counts[topics.COMMAND_TOPIC] == N


@pytest.mark.parametrize('realtime', [False, True], ids=['lockstep', 'realtime'])
def test_a_session_bag_identifies_as_recorded_by_the_sysid_loader(tmp_path, realtime):
    """No gap in the commands (real time: one a burst, held), no repeated stamp."""
    bag = tmp_path / 'bag'
    recorded, recorder = _record(bag, realtime=realtime)
    pair = [f'u_x=0.5*{topics.command_channel(0)}-0.5*{topics.command_channel(1)}']
    data = load_bag_dataset(bag, [topics.field_channel(0, 'x')], pair)  # no allow_gaps
    assert data.N == N and data.Ts == pytest.approx(2e-4)
    held, u = None, []
    for w in recorded:
        held = w.command if w.command is not None else held
        u.append(0.5 * (held[0] - held[1]))
    np.testing.assert_array_equal(data.u[:, 0], u)
    if realtime:  # one a 1 ms burst of 5 samples (the window cuts two), the one in force
        assert N // 5 <= recorder.counts[topics.COMMAND_TOPIC] <= N // 5 + 2


def test_commands_are_stamped_joint_states_under_the_contract(tmp_path, monkeypatch):
    """The contract's command type: sensor_msgs/JointState, stamp = the sample answered."""
    monkeypatch.setitem(topics.MESSAGE_TYPES, topics.COMMAND_TOPIC, 'sensor_msgs/msg/JointState')
    monkeypatch.setitem(
        topics.MESSAGE_TYPES, topics.EXCITATION_TOPIC, 'sensor_msgs/msg/JointState'
    )
    bag = tmp_path / 'bag'
    recorded, _ = _record(bag)
    from maglev_ros.bags.typestore import jazzy_typestore

    store = jazzy_typestore()
    got = {}
    with Reader(bag) as reader:
        for c, t, raw in reader.messages():
            if c.topic in ('/' + topics.COMMAND_TOPIC, '/' + topics.EXCITATION_TOPIC):
                assert c.msgtype == 'sensor_msgs/msg/JointState'
                msg = store.deserialize_cdr(raw, c.msgtype)
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                assert stamp == t and list(msg.name) == list(topics.COIL_NAMES)
                got.setdefault(c.topic, []).append(msg.effort)
    np.testing.assert_array_equal(got['/' + topics.COMMAND_TOPIC], [w.command for w in recorded])
    np.testing.assert_array_equal(
        got['/' + topics.EXCITATION_TOPIC], [w.excitation for w in recorded]
    )
