"""The recorder on a real-time loop's topics: stamped commands, stamp log times, a window.

The order of ``maglev-lab --realtime``: bursts of 5 samples (field and
currents, stamped with each sample), each followed by the one command computed
from the burst: a ``sensor_msgs/JointState`` stamped with the burst's last
sample, carrying that stamp as its value. A peer publishes them over the
middleware (reliable, so none is lost). The recorder (``log_clock: stamp``,
``record_from``, ``record_until``, given as parameters or set at run time
through its parameter service) must hold exactly the window's samples, each
command logged at the sample it answers, the command in force at the window's
start logged at its first sample and the one in force at its last sample
logged there; the bag then converts with every sample's input.
"""

import os
import subprocess
import sys

import numpy as np
import pytest
import rclpy
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, MagneticField
from waiting import wait_for

from maglev_ros.bags import BagReader, read_bag
from maglev_ros.nodes.messages import split_stamp
from maglev_ros.nodes.recorder import RecorderNode, RecorderParameterError, build_config
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.topics import COIL_NAMES, COMMAND_TOPIC, CURRENTS_TOPIC, field_topic

PERIOD_NS = 200_000  # 5 kHz
T0_NS = 1_000_000_000
N, BURST = 1000, 5
FIRST_K, LAST_K = 303, 702  # the recorded window: samples 303 .. 702 (mid-burst both)
RELIABLE = QoSProfile(depth=20000, reliability=ReliabilityPolicy.RELIABLE)


def _params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def _stamped(cls, t_ns, **fields):
    msg = cls(**fields)
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_stamp(t_ns)
    return msg


def _publish(pubs, ks, answered):
    field_pub, current_pub, command_pub = pubs
    for b0 in range(ks.start, ks.stop, BURST):
        burst = range(b0, min(b0 + BURST, ks.stop))
        for k in burst:
            t = T0_NS + k * PERIOD_NS
            field_pub.publish(_stamped(MagneticField, t))
            current_pub.publish(_stamped(JointState, t, name=list(COIL_NAMES), effort=[0.0] * 4))
        last = T0_NS + burst[-1] * PERIOD_NS
        command = _stamped(JointState, last, name=list(COIL_NAMES), effort=[last * 1e-9, 0, 0, 0])
        command.header.frame_id = 'maglev'
        command_pub.publish(command)
        answered.append(last)


@pytest.mark.parametrize('at_run_time', [False, True], ids=['parameters', 'set-at-run-time'])
def test_recorder_keeps_exactly_the_window_with_the_commands_in_force(ctx, tmp_path, at_run_time):
    first, last = T0_NS + FIRST_K * PERIOD_NS, T0_NS + LAST_K * PERIOD_NS
    window = dict(record_from=first * 1e-9, record_until=last * 1e-9)
    topics = [field_topic(0), CURRENTS_TOPIC, COMMAND_TOPIC]
    peer = rclpy.create_node('recorder_window_peer', context=ctx)
    pubs = [
        peer.create_publisher(MagneticField, field_topic(0), RELIABLE),
        peer.create_publisher(JointState, CURRENTS_TOPIC, RELIABLE),
        peer.create_publisher(JointState, COMMAND_TOPIC, RELIABLE),
    ]
    recorder = RecorderNode(
        context=ctx,
        parameter_overrides=_params(
            path=str(tmp_path / 'bag'),
            topics=topics,
            log_clock='stamp',
            metadata_node='',
            **(dict(record_from=0.0, record_until=1e-9) if at_run_time else window),
        ),
    )
    spinner = Spinner(ctx, [recorder, peer])
    answered = []
    try:
        wait_for(lambda: all(p.get_subscription_count() >= 1 for p in pubs), what='the recorder')
        _publish(pubs, range(0, 200), answered)
        if at_run_time:  # as `ros2 param set` does: through the node's parameter service
            client = peer.create_client(
                SetParametersAtomically, '/maglev_recorder/set_parameters_atomically'
            )
            assert client.wait_for_service(timeout_sec=30.0)
            request = SetParametersAtomically.Request(
                parameters=[p.to_parameter_msg() for p in _params(**window)]
            )
            future = client.call_async(request)
            wait_for(future.done, what='the window set')
            assert future.result().result.successful, future.result().result.reason
        _publish(pubs, range(200, N), answered)
        for pub in pubs:
            assert pub.wait_for_all_acked(rclpy.duration.Duration(seconds=30))
        n = LAST_K - FIRST_K + 1
        commands = 1 + sum(first <= s <= last for s in answered)  # the start's, those inside
        expected = dict(zip(topics, (n, n, commands), strict=True))
        wait_for(
            lambda: all(recorder.counts.get('/' + t, 0) >= c for t, c in expected.items()),
            what='the window',
        )
    finally:
        spinner.close()
        recorder.destroy_node()
        peer.destroy_node()
    n = LAST_K - FIRST_K + 1
    with BagReader(tmp_path / 'bag') as reader:
        logged = {}
        for topic, stamp, _ in reader.messages(['/' + t for t in topics]):
            logged.setdefault(topic, []).append(stamp)
    stamps = first + PERIOD_NS * np.arange(n)
    np.testing.assert_array_equal(logged['/' + field_topic(0)], stamps)  # the window
    assert len(logged['/' + CURRENTS_TOPIC]) == n
    inside = [s for s in answered if first <= s <= last]
    assert logged['/' + COMMAND_TOPIC] == [first, *inside, last]
    data = read_bag(
        tmp_path / 'bag',
        [f'b={field_topic(0)}:magnetic_field.x'],
        [f'c={COMMAND_TOPIC}:data[0]'],  # the old spelling reads the JointState's effort
        allow_gaps=True,
    ).data
    assert data.N == n  # every sample has its input: nothing trimmed
    held = np.array([max(s for s in answered if s <= t) for t in stamps])
    np.testing.assert_allclose(np.asarray(data.u)[:, 0], held * 1e-9, rtol=0, atol=1e-12)


def test_the_removed_intra_process_is_refused_with_what_replaced_it(ctx, domain, tmp_path):
    with pytest.raises(RecorderParameterError, match='intra_process was removed: the recorder'):
        RecorderNode(
            context=ctx, parameter_overrides=_params(path=str(tmp_path / 'a'), intra_process=True)
        )
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    command = [sys.executable, '-m', 'maglev_ros.nodes.recorder', '--ros-args', '-p',
               f'path:={tmp_path / "b"}', '-p', 'intra_process:=false']  # fmt: skip
    proc = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and 'intra_process was removed' in lines[0], lines
    assert not (tmp_path / 'a').exists() and not (tmp_path / 'b').exists()  # no bag begun


def test_a_window_set_at_run_time_is_checked_and_keeps_the_bag(ctx, tmp_path):
    recorder = RecorderNode(
        context=ctx,
        parameter_overrides=_params(
            path=str(tmp_path / 'bag'), record_until=3.0, metadata_node=''
        ),
    )
    try:  # the bag exists now: a change of the window does not check its path again
        result = recorder.set_parameters_atomically(_params(record_from=4.0))
        assert not result.successful and 'record_until must be 0' in result.reason
        assert (recorder.config.record_from, recorder.config.record_until) == (0.0, 3.0)
        assert recorder.set_parameters_atomically(_params(record_from=4.0, record_until=5.0))
        assert (recorder.config.record_from, recorder.config.record_until) == (4.0, 5.0)
        assert recorder.config.path == str(tmp_path / 'bag')
        assert not recorder.set_parameters_atomically(_params(path='elsewhere')).successful
    finally:
        recorder.destroy_node()


def test_window_and_log_clock_are_checked(tmp_path):
    path = str(tmp_path / 'bag')
    with np.testing.assert_raises_regex(RecorderParameterError, 'record_until must be 0'):
        build_config({'path': path, 'record_from': 2.0, 'record_until': 1.0})
    cfg = build_config({'path': path, 'log_clock': 'stamp', 'record_until': 1.0})
    assert cfg.log_clock == 'stamp' and cfg.record_until == 1.0
    assert not hasattr(cfg, 'intra_process')  # removed (see the test below)
