"""The driver composed with the closed loop's nodes (``intra_process``): ``maglev-lab --board``.

A V2x virtual board (linear plant) streams records; the driver
(``intra_process: true``) must hand each read to a listener of its samples
channel as stamps, fields (T) and currents (A), equal to what it publishes;
give a tap listener the very bytes it publishes, taps before the channel (a
command computed from a read follows its samples); take the commands of a
controller of its process through its command sink, guarded and scaled like
the subscription's, which it then drops (one command source).
"""

import time
from functools import partial

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState, MagneticField
from waiting import wait_for

from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.virtual_board import VirtualBoard
from maglev_ros.nodes import intra_process
from maglev_ros.nodes.driver import DriverNode
from maglev_ros.nodes.messages import command_message
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.topics import COMMAND_TOPIC, CURRENTS_TOPIC, field_topic

N_SENSORS = 2
COUNTS_PER_A = 1000.0
RELIABLE_DEEP = QoSProfile(depth=20000, reliability=ReliabilityPolicy.RELIABLE)


def _driver(ctx, port, **params):
    values = dict(
        port=port,
        n_sensors=N_SENSORS,
        counts_per_ampere=COUNTS_PER_A,
        start_enabled=True,
        command_timeout=1.0,
        intra_process=True,
        confirm_records=False,
    )
    values.update(params)
    return DriverNode(
        context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in values.items()]
    )


@pytest.fixture
def board():
    plant = LinearPlant.default(N_SENSORS)
    with VirtualBoard(partial(V2xFirmware, plant, N_SENSORS, startup_delay=0.2)) as b:
        yield b


def _accepted(board):
    with board.lock:
        return [tuple(p) for _, p in board.firmware.accepted]


def test_samples_and_taps_carry_what_is_published(ctx, board):
    driver = _driver(ctx, board.path)
    blocks, tapped, order = [], {}, []
    peer = rclpy.create_node('driver_composed_peer', context=ctx)
    published = {0: [], 1: [], 'currents': []}
    for k in range(N_SENSORS):
        peer.create_subscription(
            MagneticField, field_topic(k), published[k].append, RELIABLE_DEEP, raw=True
        )
    peer.create_subscription(
        JointState, CURRENTS_TOPIC, published['currents'].append, RELIABLE_DEEP, raw=True
    )
    taps = {
        topic: intra_process.tap(ctx, '/' + topic)
        for topic in [field_topic(0), field_topic(1), CURRENTS_TOPIC]
    }
    for topic, t in taps.items():
        t.connect(lambda msgs, topic=topic: (tapped.setdefault(topic, []).extend(msgs),
                                             order.append('tap')), 'test')  # fmt: skip
    source = intra_process.find(ctx, driver.resolve_topic_name(CURRENTS_TOPIC))
    assert source is driver.samples_source and source.sensors == (0, 1)
    source.connect(lambda block: (blocks.append(block), order.append('block')), 'test')
    spinner = Spinner(ctx, [driver, peer])
    try:
        assert taps[CURRENTS_TOPIC].msgtype == 'sensor_msgs/msg/JointState'
        wait_for(lambda: sum(len(b) for b in blocks) > 2000, timeout=30.0, what='0.4 s of records')
        wait_for(lambda: len(published['currents']) >= 1000, timeout=30.0, what='the subscriber')
    finally:
        spinner.close()
        driver.destroy_node()
        peer.destroy_node()
    stamps = np.concatenate([b.stamps_ns for b in blocks])
    readings = np.concatenate([b.readings for b in blocks])
    currents = np.concatenate([b.currents for b in blocks])
    assert readings.shape == (len(stamps), 3 * N_SENSORS) and currents.shape == (len(stamps), 4)
    assert np.all(np.diff(stamps) > 0)
    # every read: its taps first, then its block (a command follows its samples)
    assert order[:4] == ['tap', 'tap', 'tap', 'block'] and order.count('block') == len(blocks)
    # the taps get the messages as published: the same bytes, the same count
    n = len(stamps)
    for topic in [field_topic(0), field_topic(1), CURRENTS_TOPIC]:
        assert len(tapped[topic]) == n
    for k, topic in enumerate([field_topic(0), field_topic(1)]):
        for i in (0, n // 2, n - 1):
            msg = deserialize_message(tapped[topic][i], MagneticField)
            assert msg.header.frame_id == f'maglev_sensor_{k}'
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == stamps[i]
            f = msg.magnetic_field
            np.testing.assert_array_equal([f.x, f.y, f.z], readings[i, 3 * k : 3 * k + 3])
    got = set(published[0]) & set(tapped[field_topic(0)])
    assert len(got) >= 1000  # the subscriber's messages are the tapped ones
    mt = LinearPlant.default(N_SENSORS)(np.zeros(4), 0.0)  # no command came: zero PWM
    np.testing.assert_array_equal(readings[-1], mt.astype(np.float32).astype(float).ravel() * 1e-3)
    np.testing.assert_array_equal(currents, 0.0)


def test_a_composed_controller_takes_over_the_command_input(ctx, board):
    driver = _driver(ctx, board.path, current_limit=1.0)
    command_topic = driver.resolve_topic_name(COMMAND_TOPIC)
    peer = rclpy.create_node('driver_composed_commands', context=ctx)
    commands = peer.create_publisher(JointState, COMMAND_TOPIC, 10)
    spinner = Spinner(ctx, [driver, peer])
    try:
        wait_for(lambda: commands.get_subscription_count() > 0, what='the command subscription')
        sink = intra_process.find(ctx, driver.resolve_topic_name(COMMAND_TOPIC))
        assert isinstance(sink, intra_process.CommandSink) and sink.lock is None
        take = sink.attach('test_controller')
        assert take is not None and sink.attach('another') is None  # one source
        wait_for(lambda: commands.get_subscription_count() == 0, what='the subscription dropped')
        take([0.25, -0.5, 2.0, float('nan')])  # rejected: nothing sent
        take([0.25, -0.5, 2.0, 0.0])  # clamped to the 1 A limit
        wait_for(lambda: (250, -500, 1000, 0) in _accepted(board), what='the command')
        assert driver.counters['commands_rejected'] == 1
        assert driver.counters['commands_clamped'] == 1
        commands.publish(command_message(0, [0.1, 0.1, 0.1, 0.1]))  # nobody listens
        time.sleep(0.3)
    finally:
        spinner.close()
        driver.destroy_node()
        peer.destroy_node()
    assert (100, 100, 100, 100) not in _accepted(board)
    wait_for(lambda: _accepted(board)[-1] == (0, 0, 0, 0), what='zero currents at the end')
    assert intra_process.find(ctx, command_topic) is None
    assert intra_process.tap(ctx, '/' + CURRENTS_TOPIC).publishers == 0


def test_the_port_opens_at_start_when_asked_to_wait(ctx, board):
    """``open_port=False``: a composed lab builds every node, then starts the board."""
    driver = DriverNode(
        open_port=False,
        context=ctx,
        parameter_overrides=[Parameter('port', value=board.path), Parameter('n_sensors', value=2)],
    )
    try:
        time.sleep(0.3)
        assert not board.status.port_open and driver.link_state == 'connecting'
        driver.start()
        driver.start()  # idempotent
        wait_for(lambda: driver.counters['records'] > 0, what='records after start')
        assert board.status.port_open
    finally:
        driver.destroy_node()
    never = DriverNode(
        open_port=False,
        context=ctx,
        parameter_overrides=[Parameter('port', value=board.path), Parameter('n_sensors', value=2)],
    )
    never.destroy_node()  # never started: closes cleanly
