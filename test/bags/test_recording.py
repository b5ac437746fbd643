"""A recording: serialised messages -> bag at their log times, inside a window; read back.

The messages are built and serialised with rosbags (no rclpy), in the order a
real-time simulator publishes them: bursts of 5 samples (field and currents
stamped with each sample), then the one command computed from the burst,
carrying as its value the stamp of the burst's last sample. The command is
either the stamped ``sensor_msgs/JointState`` (``effort``, header stamp = the
sample it answers) or the header-less ``std_msgs/Float64MultiArray`` of older
publishers; both bags convert with either spelling of the command channel.
"""

import numpy as np
import pytest

from maglev_ros.bags import BagError, BagReader, BagWriter, read_bag
from maglev_ros.bags.recording import LogClock, Recording, RecordingConfig, header_stamp_ns
from maglev_ros.bags.typestore import jazzy_typestore
from maglev_ros.topics import CLOCK_TOPIC, COIL_NAMES, COMMAND_TOPIC, CURRENTS_TOPIC, field_topic

STORE = jazzy_typestore()
T = STORE.types
PERIOD_NS = 200_000  # 5 kHz
T0_NS = 1_000_000_000
FIELD, CURRENTS, COMMAND = '/' + field_topic(0), '/' + CURRENTS_TOPIC, '/' + COMMAND_TOPIC


def header(stamp_ns, frame=''):
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=frame
    )


def serialise(msg, msgtype):
    return bytes(STORE.serialize_cdr(msg, msgtype))


def field_msg(stamp_ns, x):
    vec = T['geometry_msgs/msg/Vector3'](x=float(x), y=0.0, z=0.05)
    msg = T['sensor_msgs/msg/MagneticField'](
        header=header(stamp_ns, 'maglev_sensor_0'),
        magnetic_field=vec,
        magnetic_field_covariance=np.zeros(9),
    )
    return serialise(msg, 'sensor_msgs/msg/MagneticField')


def joint_state(stamp_ns, effort, frame='maglev'):
    msg = T['sensor_msgs/msg/JointState'](
        header=header(stamp_ns, frame),
        name=list(COIL_NAMES),
        position=np.zeros(0),
        velocity=np.zeros(0),
        effort=np.asarray(effort, dtype=float),
    )
    return serialise(msg, 'sensor_msgs/msg/JointState')


def float_array(values):
    layout = T['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0)
    msg = T['std_msgs/msg/Float64MultiArray'](layout=layout, data=np.asarray(values, float))
    return serialise(msg, 'std_msgs/msg/Float64MultiArray')


def clock_msg(stamp_ns):
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    msg = T['rosgraph_msgs/msg/Clock'](
        clock=T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)
    )
    return serialise(msg, 'rosgraph_msgs/msg/Clock')


def realtime_run(n, burst, stamped_commands):
    """Messages of ``n`` samples in bursts: (topic, bytes), and the commands' answered stamps."""
    messages, answered = [], []
    for b0 in range(0, n, burst):
        ks = range(b0, min(b0 + burst, n))
        for k in ks:
            messages.append((FIELD, field_msg(T0_NS + k * PERIOD_NS, 1e-3 * k)))
        for k in ks:
            messages.append((CURRENTS, joint_state(T0_NS + k * PERIOD_NS, [0.1 * k, 0, 0, 0])))
        last = T0_NS + ks[-1] * PERIOD_NS
        value = [last * 1e-9, -1.0, 0.5, 0.0]
        answer = joint_state(last, value) if stamped_commands else float_array(value)
        messages.append((COMMAND, answer))
        answered.append(last)
    return messages, answered


def record(path, messages, stamped_commands, log_clock='stamp', window=(0, None)):
    writer = BagWriter(path, metadata={'test': 1}).open()
    recording = Recording(writer, log_clock, now=lambda: 0, start_ns=window[0], end_ns=window[1])
    recording.add_topic(FIELD, 'sensor_msgs/msg/MagneticField', stamped=True)
    recording.add_topic(CURRENTS, 'sensor_msgs/msg/JointState', stamped=True)
    command_type = (
        'sensor_msgs/msg/JointState' if stamped_commands else 'std_msgs/msg/Float64MultiArray'
    )
    recording.add_topic(COMMAND, command_type, stamped=stamped_commands)
    for topic, data in messages:
        recording.write(topic, data)
    recording.close()
    assert recording.closed and recording.write(FIELD, messages[0][1]) == 0
    return recording


@pytest.mark.parametrize('stamped', [True, False], ids=['JointState', 'Float64MultiArray'])
@pytest.mark.parametrize('spelling', ['data', 'effort'])
def test_a_window_of_a_realtime_run_converts_with_every_command_held(tmp_path, stamped, spelling):
    n, first_k, last_k = 200, 52, 143  # the window: samples 52 .. 143
    first, last = T0_NS + first_k * PERIOD_NS, T0_NS + last_k * PERIOD_NS
    messages, answered = realtime_run(n, 5, stamped)
    recording = record(tmp_path / 'bag', messages, stamped, window=(first, last))
    with BagReader(tmp_path / 'bag') as reader:
        logged = {}
        for topic, log_time, _ in reader.messages([FIELD, CURRENTS, COMMAND]):
            logged.setdefault(topic, []).append(log_time)
    window_stamps = first + PERIOD_NS * np.arange(last_k - first_k + 1)
    np.testing.assert_array_equal(logged[FIELD], window_stamps)
    np.testing.assert_array_equal(logged[CURRENTS], window_stamps)
    # the command in force at the start, each answer at its sample, the last one once
    # more at the window's last sample
    inside = [s for s in answered if first <= s <= last]
    assert logged[COMMAND] == [first, *inside, last]
    assert recording.counts[COMMAND] == len(inside) + 2
    data = read_bag(
        tmp_path / 'bag',
        [f'b={FIELD}:magnetic_field.x'],
        [f'c={COMMAND}:{spelling}[0]', f'u1={COMMAND}:{spelling}[1]'],
        allow_gaps=True,
    )
    assert data.data.N == len(window_stamps)  # every sample has its input: nothing trimmed
    assert tuple(data.data.input_units) == ('A', 'A')
    held = [max(s for s in answered if s <= t) for t in window_stamps]
    np.testing.assert_allclose(np.asarray(data.data.u)[:, 0], np.array(held) * 1e-9, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(data.data.u)[:, 1], -1.0)


@pytest.mark.parametrize('stamped', [True, False], ids=['JointState', 'Float64MultiArray'])
def test_a_lockstep_run_logged_by_its_clock_pairs_command_k_with_sample_k(tmp_path, stamped):
    n = 50
    messages = []
    for k in range(n):
        t = T0_NS + k * PERIOD_NS
        messages += [
            (CLOCK_TOPIC, clock_msg(t)),
            (FIELD, field_msg(t, 1e-3 * k)),
            (COMMAND, joint_state(t, [k, 0, 0, 0]) if stamped else float_array([k, 0, 0, 0])),
        ]
    writer = BagWriter(tmp_path / 'bag').open()
    recording = Recording(writer, 'topic', now=lambda: 0)
    recording.add_topic(CLOCK_TOPIC, 'rosgraph_msgs/msg/Clock', stamped=False)
    recording.add_topic(FIELD, 'sensor_msgs/msg/MagneticField', stamped=True)
    command_type = 'sensor_msgs/msg/JointState' if stamped else 'std_msgs/msg/Float64MultiArray'
    recording.add_topic(COMMAND, command_type, stamped=stamped)
    for topic, data in messages:
        recording.write(topic, data)
    recording.close()
    data = read_bag(tmp_path / 'bag', [f'{FIELD}:magnetic_field.x'], [f'{COMMAND}:data[0]'])
    np.testing.assert_array_equal(np.asarray(data.data.u)[:, 0], np.arange(n))
    assert data.alignment.gaps == ()


def test_log_clocks():
    now = iter([7, 8])
    clock = LogClock('ros', lambda: next(now))
    assert clock.log_time(b'', stamped=False) == 7
    stamp = LogClock('stamp', lambda: 0)
    assert stamp.log_time(float_array([1.0]), stamped=False) == 0  # nothing recorded yet
    assert stamp.log_time(field_msg(5_000_000_123, 0.0), stamped=True) == 5_000_000_123
    assert stamp.log_time(field_msg(4_000_000_000, 0.0), stamped=True) == 4_000_000_000
    assert stamp.log_time(float_array([1.0]), stamped=False) == 5_000_000_123  # the newest
    topic = LogClock('topic', lambda: 0)
    assert topic.log_time(field_msg(9, 0.0), stamped=True) == 0
    assert topic.log_time(clock_msg(3_000_000_001), True, is_clock=True) == 3_000_000_001
    assert topic.log_time(field_msg(9, 0.0), stamped=True) == 3_000_000_001
    with pytest.raises(BagError, match="log clock must be one of ros, topic, stamp, got 'wall'"):
        LogClock('wall', lambda: 0)
    with pytest.raises(BagError, match='at least 12 bytes, got 4'):
        header_stamp_ns(b'\x00\x01\x00\x00')


def test_the_config_gives_the_window_and_the_metadata(tmp_path):
    cfg = RecordingConfig(str(tmp_path), 'mcap', ('/a',), 10, 'stamp', '', 0.25, 0.0)
    assert cfg.window_ns == (250_000_000, None)
    meta = cfg.metadata()
    assert meta['recorder.log_clock'] == 'stamp' and meta['recorder.topics'] == '/a'
    assert 'recorder.intra_process' not in meta
