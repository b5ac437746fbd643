"""The loop node: the closed loop composed in one process, its topics for observers."""

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


def test_bad_loop_parameters_name_the_problem(ctx):
    with pytest.raises(LoopParameterError, match=r'control_rate must divide sample_rate'):
        LoopNode(context=ctx, parameter_overrides=[Parameter('control_rate', value=3000.0)])
    with pytest.raises(LoopParameterError, match=r'filter must be one of kf, ekf, ukf'):
        LoopNode(context=ctx, parameter_overrides=[Parameter('filter', value='pf')])
