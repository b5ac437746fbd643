"""The closed loop's real-time settings, each checked deterministically.

* the estimator's ``publish_rate``: only the estimates of samples whose stamp
  is a multiple of the publishing period go out (the filter steps every sample);
* the controller's ``trigger: estimate``: zero commands while no estimate came
  (it is up and hears an estimator), one command per estimate, and when the estimates stop for
  ``input_timeout`` one zero command and an ERROR; after a stall it answers only the
  newest estimate that came meanwhile (keep-last 1);
* the simulator's ``wait_for_controller``: real time starts only at the first
  command.

Messages are fed to the nodes' own callbacks as the raw bytes a ``raw=True``
subscription delivers, so nothing here depends on the machine's speed but the
(generous) waits for a message to arrive.
"""

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState, MagneticField
from waiting import wait_for

from maglev_ros import topics
from maglev_ros.loop.commander import READY_AFTER_S
from maglev_ros.nodes.controller import ControllerNode
from maglev_ros.nodes.estimator import EstimatorNode
from maglev_ros.nodes.messages import command_message, odometry_message
from maglev_ros.nodes.qos import LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.nodes.simulator import SimulatorNode
from maglev_ros.physics import make_model
from maglev_ros.physics.equilibria import find_equilibria

PERIOD_NS = 200_000  # 5 kHz


def _params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def _stamped(msg, t_ns):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
    return msg


def _listener(ctx, msgtype, topic, qos):
    import rclpy

    node = rclpy.create_node(f'listener_{topic.replace("/", "_")}', context=ctx)
    got = []
    node.create_subscription(msgtype, topic, got.append, qos)
    return node, got


def test_estimator_publishes_the_estimates_of_its_publish_rate(ctx):
    model = make_model('maggy_v2')
    x_eq = model.hover_state(find_equilibria(model)[0].z)
    y_eq = model.measurement(x_eq, np.zeros(4))
    est = EstimatorNode(context=ctx, parameter_overrides=_params(publish_rate=1000.0))
    listener, got = _listener(ctx, Odometry, topics.ESTIMATE_TOPIC, SENSOR_QOS)
    spinner = Spinner(ctx, [listener])
    try:
        wait_for(lambda: est._pub.get_subscription_count() >= 1, what='discovery')
        stamps = [(7 + k) * PERIOD_NS for k in range(23)]  # samples 7 .. 29
        for t in stamps:
            for s in range(3):
                field = _stamped(MagneticField(), t)
                v = field.magnetic_field
                v.x, v.y, v.z = map(float, y_eq[3 * s : 3 * s + 3])
                est._on_field(s, serialize_message(field))
            currents = _stamped(JointState(), t)
            currents.name, currents.effort = ['x+', 'x-', 'y+', 'y-'], [0.0] * 4
            est._on_currents(serialize_message(currents))
        expected = [t for t in stamps if t % (5 * PERIOD_NS) == 0]  # samples 10, 15, 20, 25
        wait_for(lambda: len(got) >= len(expected), what='the estimates')
        time.sleep(0.2)  # nothing more arrives
        assert [m.header.stamp.nanosec for m in got] == expected
        assert est.estimator.samples == len(stamps)  # the filter stepped every sample
    finally:
        spinner.close()
        est.destroy_node()


def _realtime_controller(ctx, input_timeout: float, diagnostics_period: float):
    """A controller on estimates at 1 kHz, and the equilibrium state it holds."""
    model = make_model('maggy_v2')
    x_eq = model.hover_state(find_equilibria(model)[0].z)
    ctrl = ControllerNode(
        context=ctx,
        parameter_overrides=_params(
            trigger='estimate',
            sample_rate=1000.0,
            input_timeout=input_timeout,
            diagnostics_period=diagnostics_period,
        ),
    )
    return ctrl, x_eq


def test_controller_answers_each_estimate_and_zeroes_when_they_stop(ctx):
    ctrl, x_eq = _realtime_controller(ctx, input_timeout=0.05, diagnostics_period=10.0)
    listener, commands = _listener(ctx, JointState, topics.COMMAND_TOPIC, LOCKSTEP_COMMAND_QOS)
    diags = []
    listener.create_subscription(
        DiagnosticArray, topics.DIAGNOSTICS_TOPIC, lambda m: diags.extend(m.status), 10
    )
    spinner = Spinner(ctx, [listener, ctrl])
    try:
        wait_for(lambda: ctrl._pub.get_subscription_count() >= 1, what='discovery')
        time.sleep(2 * READY_AFTER_S)  # no estimator heard: not ready, no command
        assert commands == []
        listener.create_publisher(Odometry, topics.ESTIMATE_TOPIC, SENSOR_QOS)  # one now
        heard = time.monotonic()
        # up, spinning, an estimator heard for READY_AFTER_S, no estimate yet: zero
        # commands every input_timeout (the simulator's wait_for_controller starts on them)
        wait_for(lambda: len(commands) >= 2, what='the ready commands')
        assert time.monotonic() - heard >= READY_AFTER_S
        assert all(list(c.effort) == [0.0] * 4 for c in commands)
        x = x_eq.copy()
        x[0] += 2e-4  # 0.2 mm off in x: the LQR pushes back
        for k in range(5):
            ctrl._on_estimate_only(odometry_message((k + 1) * 1_000_000, x))
        answers = ctrl.commands  # published so far: the ready ones, then one per estimate
        wait_for(lambda: len(commands) >= answers, what='one command per estimate')
        pushed = [np.array(c.effort) for c in commands[:answers] if any(c.effort)]
        assert len(pushed) == 5 and all(np.all(np.abs(c) <= 1.0) for c in pushed)
        # silence: after input_timeout (50 ms of the node's clock) one zero command
        wait_for(lambda: len(commands) >= answers + 1, timeout=60.0, what='the zero command')
        assert list(commands[answers].effort) == [0.0] * 4
        wait_for(
            lambda: any(s.level == DiagnosticStatus.ERROR for s in diags),
            timeout=60.0,
            what='an ERROR on /diagnostics',
        )
        time.sleep(0.3)
        assert len(commands) == answers + 1  # once per silence, no more ready commands
    finally:
        spinner.close()
        ctrl.destroy_node()


def test_a_stalled_controller_answers_only_the_newest_estimate(ctx):
    """Estimates queued while the controller did not spin: one answer, to the newest."""
    import rclpy

    ctrl, x_eq = _realtime_controller(ctx, input_timeout=30.0, diagnostics_period=30.0)
    source = rclpy.create_node('estimates', context=ctx)
    pub = source.create_publisher(Odometry, topics.ESTIMATE_TOPIC, SENSOR_QOS)
    try:
        wait_for(lambda: pub.get_subscription_count() >= 1, what='discovery')
        for k in range(20):  # the controller does not spin: a stall
            pub.publish(odometry_message((k + 1) * 1_000_000, x_eq))
        time.sleep(0.5)  # delivered to its subscription meanwhile
        spinner = Spinner(ctx, [ctrl])
        try:
            wait_for(lambda: ctrl.commands >= 1, what='an answer')
            time.sleep(0.5)
        finally:
            spinner.close()
        assert ctrl.commands == 1
        assert ctrl.controller.watchdog.last_input == 20e-3  # the newest estimate's stamp
    finally:
        source.destroy_node()
        ctrl.destroy_node()


def test_realtime_simulator_waits_for_its_controller(ctx):
    import rclpy

    sim = SimulatorNode(
        context=ctx,
        parameter_overrides=_params(
            mode='realtime', magnet='free', marker_rate=0.0, wait_for_controller=True
        ),
    )
    spinner = Spinner(ctx, [sim])
    try:
        node = rclpy.create_node('a_controller', context=ctx)
        pub = node.create_publisher(JointState, topics.COMMAND_TOPIC, 10)
        wait_for(lambda: sim.command_publishers >= 1, what='discovery')
        time.sleep(0.5)  # a publisher is not yet a controller: no command, no step
        assert sim.counters['samples'] == 0 and not sim.session.started

        def commanded():
            pub.publish(command_message(0, [0.0] * 4))
            return sim.counters['samples'] > 0

        wait_for(commanded, timeout=60.0, period=0.05, what='stepping on the first command')
        node.destroy_node()
    finally:
        spinner.close()
        sim.destroy_node()
