"""The loop node: the closed loop composed in one process, its topics for observers."""

import gc
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.nodes.loop import LoopNode, LoopParameterError
from maglev_ros.nodes.qos import SENSOR_QOS

WAIT_S = 120.0  # s: the first construction compiles the kernels


def test_the_loop_node_publishes_samples_estimates_and_commands_in_stamp_order(ctx):
    loop = LoopNode(context=ctx, parameter_overrides=[Parameter('diagnostics_period', value=0.2)])
    # the node's objects were frozen out of the garbage collector's way before its loop ran
    assert gc.get_freeze_count() > 10_000
    listener = Node('listener', context=ctx)
    got = {'field': [], 'currents': [], 'estimate': [], 'command': [], 'true': [], 'diag': []}

    def keep(key):
        return lambda msg: got[key].append(msg)

    for key, msg_type, topic in [
        ('field', MagneticField, 'maglev/sensor_0/field'),
        ('currents', JointState, 'maglev/currents'),
        ('estimate', Odometry, 'maglev/state/estimate'),
        ('command', JointState, 'maglev/currents/command'),
        ('true', Odometry, 'maglev/state/true'),
    ]:
        listener.create_subscription(msg_type, topic, keep(key), SENSOR_QOS)
    listener.create_subscription(DiagnosticArray, '/diagnostics', keep('diag'), 10)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(listener)
    executor.add_node(loop)  # its diagnostics timer
    try:
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline and (len(got['true']) < 500 or not got['diag']):
            executor.spin_once(timeout_sec=0.1)
    finally:
        loop.destroy_node()
        listener.destroy_node()
    assert min(len(v) for v in got.values()) > 0, {k: len(v) for k, v in got.items()}

    def stamps(key):
        return np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in got[key]])

    # one sample per control period (1 kHz), stamped on the simulated time base, in order
    s = stamps('currents')
    assert np.all(np.diff(s) > 0) and np.all(np.diff(s) % 200_000 == 0)
    assert set(stamps('estimate')) <= set(s) | set(stamps('true'))
    assert all(len(m.effort) == 4 and max(map(abs, m.effort)) <= 1.0 for m in got['command'])
    assert got['field'][0].header.frame_id == 'maglev_sensor_0'
    status = got['diag'][-1].status[0]
    assert status.name == 'maglev_loop: loop'
    values = {kv.key: kv.value for kv in status.values}
    assert int(values['broadcast_published']) > 0 and values['controller'] in ('OK', 'ERROR')


def test_the_loop_starts_once_its_start_reader_reads_the_command_and_the_estimate(ctx):
    """With ``start_reader`` the loop waits (nothing published) until that node subscribes."""
    loop = LoopNode(context=ctx, parameter_overrides=[
        Parameter('start_reader', value='maglev_test_recorder')])  # fmt: skip
    listener = Node('listener', context=ctx)
    currents = []
    listener.create_subscription(JointState, 'maglev/currents', currents.append, SENSOR_QOS)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (listener, loop):
        executor.add_node(node)
    recorder = None
    try:
        deadline = time.monotonic() + 1.0  # fifty looks at the graph, no reader
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert not loop.started and currents == []
        assert loop.status[1] == 'waiting for the start_reader to read its topics'
        recorder = Node('maglev_test_recorder', context=ctx)  # not spun: its subscriptions only

        def ignore(msg):
            pass

        recorder.create_subscription(JointState, 'maglev/currents/command', ignore, SENSOR_QOS)
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline and not loop.started:
            executor.spin_once(timeout_sec=0.05)
        assert not loop.started, 'started before its reader read maglev/state/estimate'
        recorder.create_subscription(Odometry, 'maglev/state/estimate', ignore, SENSOR_QOS)
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline and len(currents) < 100:
            executor.spin_once(timeout_sec=0.05)
        assert loop.started and len(currents) >= 100
    finally:
        loop.destroy_node()
        listener.destroy_node()
        if recorder is not None:
            recorder.destroy_node()


def test_bad_loop_parameters_name_the_problem(ctx):
    with pytest.raises(LoopParameterError, match=r'control_rate must divide sample_rate'):
        LoopNode(context=ctx, parameter_overrides=[Parameter('control_rate', value=3000.0)])
    with pytest.raises(LoopParameterError, match=r'filter must be one of kf, ekf, ukf'):
        LoopNode(context=ctx, parameter_overrides=[Parameter('filter', value='pf')])
    board = [Parameter('plant', value='board'), Parameter('firmware', value='v4x_pc')]
    with pytest.raises(LoopParameterError, match=r'maglev-lab --firmware v4x_pc --board PORT'):
        LoopNode(context=ctx, parameter_overrides=board)


def test_the_loop_node_runs_on_a_board_and_leaves_its_coils_at_zero(ctx):
    """plant: board: the board's stream paces the loop; its fields are published, commands
    reach the board, and the node's end sends zero currents."""
    from functools import partial

    from waiting import wait_for

    from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
    from maglev_ros.hardware.virtual_board import VirtualBoard

    firmware = partial(V2xFirmware, LinearPlant.default(3), 3, startup_delay=0.2)
    with VirtualBoard(firmware) as board:
        loop = LoopNode(
            context=ctx,
            parameter_overrides=[
                Parameter('plant', value='board'),
                Parameter('port', value=board.path),
                Parameter('n_sensors', value=3),
                Parameter('diagnostics_period', value=0.2),
            ],
        )
        listener = Node('listener', context=ctx)
        fields, commands = [], []
        listener.create_subscription(
            MagneticField, 'maglev/sensor_2/field', fields.append, SENSOR_QOS
        )
        listener.create_subscription(
            JointState, 'maglev/currents/command', commands.append, SENSOR_QOS
        )
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(listener)
        try:

            def heard() -> bool:
                executor.spin_once(timeout_sec=0.05)
                return len(fields) >= 50 and len(commands) >= 50

            wait_for(heard, timeout=WAIT_S, what='the board fields and the commands')
            assert loop.plant.counters['commands_sent'] > 0
        finally:
            loop.destroy_node()
            listener.destroy_node()
        with board.lock:
            last = board.firmware.accepted[-1][1]
        assert tuple(last) == (0, 0, 0, 0)  # the node's end: zero currents
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in fields]
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))
    assert fields[0].header.frame_id == 'maglev_sensor_2'


def test_a_board_that_is_not_there_is_named(ctx, tmp_path):
    with pytest.raises(LoopParameterError, match=str(tmp_path / 'no_board')):
        LoopNode(
            context=ctx,
            parameter_overrides=[
                Parameter('plant', value='board'),
                Parameter('port', value=str(tmp_path / 'no_board')),
            ],
        )
