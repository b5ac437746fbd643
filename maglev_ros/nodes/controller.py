"""Levitation controller node: ``ros2 run maglev_ros controller``.

Runs the ROS-free control law of :mod:`maglev_ros.control` (``mode`` ``lqr``:
state feedback on ``maglev/state/estimate``; ``pd``: the firmware's PD on the
raw fields; every :class:`~maglev_ros.control.ControllerConfig` setting is a
parameter, defaults as ``config/controller.yaml``) through
:class:`~maglev_ros.loop.commander.Commander`, and publishes
``maglev/currents/command`` (sensor_msgs/JointState: names x+ x- y+ y-,
effort in A clipped at ``current_limit``, stamped with the sample it answers).

``trigger: sample`` (lockstep): exactly one command per sample, its parts
(currents and estimate, or every field and the currents) paired by stamp in
any order; ``delay_commands`` publishes for sample k the command computed at
k - 1 (the board's timing). ``trigger: estimate`` (real time): one command per
estimate taken, the newest (keep-last 1: after a stall, the ones queued meanwhile
are skipped); when they stop, zero currents and an ERROR. With
``excitation_signal`` set, the excitation part of each command is published
just before it on ``maglev/currents/excitation`` (the IV's instruments).

Stale input: zero currents and an ERROR on ``/diagnostics`` at once, re-armed
after ``rearm_samples`` fresh inputs. ``maglev/controller/enable`` (SetBool)
switches it; ``maglev/reference`` (PoseStamped) moves the LQR's set-point.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState, MagneticField
from std_srvs.srv import SetBool

from maglev_ros.control import ControllerConfig, ControllerConfigError, make_controller
from maglev_ros.control.excitation import (
    EXCITATION_PARAMETERS,
    CommandExcitation,
    LoopExcitationError,
    excitation_from_parameters,
)
from maglev_ros.loop.commander import TRIGGERS, Commander, check_trigger
from maglev_ros.nodes.messages import command_message, diagnostic_array, stamp_ns
from maglev_ros.nodes.params import (
    PARAMS,
    NodeParameterError,
    Param,
    ParameterTable,
    choice,
    config_params,
    number,
)
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS, LATEST_QOS, LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.nodes.state_messages import odometry_state
from maglev_ros.topics import (
    COMMAND_TOPIC,
    CONTROLLER_ENABLE_SERVICE,
    CURRENTS_TOPIC,
    DIAGNOSTICS_TOPIC,
    ESTIMATE_TOPIC,
    EXCITATION_TOPIC,
    REFERENCE_TOPIC,
    field_topic,
)

__all__ = ['PARAMETERS', 'ControllerNode', 'ControllerNodeConfig', 'ControllerParameterError']
__all__ += ['build_config', 'main']

NODE_NAME = 'maglev_controller'


class ControllerParameterError(NodeParameterError):
    """A controller parameter has an invalid value."""


@dataclass(frozen=True)
class ControllerNodeConfig:
    """Validated controller-node parameters (their meanings: :data:`PARAMETERS`).

    Attributes
    ----------
    params, trigger : str
    controller : ControllerConfig
    delay_commands, start_enabled : bool
    diagnostics_period : float
    excitation : CommandExcitation
    """

    params: str
    controller: ControllerConfig
    delay_commands: bool
    start_enabled: bool
    diagnostics_period: float
    trigger: str = 'sample'
    excitation: CommandExcitation = CommandExcitation()


PARAMETERS = ParameterTable(
    NODE_NAME,
    ControllerParameterError,
    {
        'params': PARAMS,
        **config_params(ControllerConfig),
        'delay_commands': Param(
            False,
            'publish each command one sample late (lockstep simulation: the one-sample '
            'command latency of the board that command_delay designs for)',
        ),
        'start_enabled': Param(True, f'enabled at start (then {CONTROLLER_ENABLE_SERVICE})'),
        'diagnostics_period': Param(
            0.5, 's of the node clock between diagnostics', check=number(0, above=True)
        ),
        'trigger': Param(
            'sample',
            'sample: one command per sample (currents + estimate of a stamp; lockstep), '
            'estimate: one command per estimate (LQR in real time at the estimator '
            'publish_rate; sample_rate is then that rate)',
            check=choice(*TRIGGERS),
        ),
        **EXCITATION_PARAMETERS,
    },
    removed={
        'intra_process': 'the composed loop runs the hot path as direct calls '
        '(ros2 run maglev_ros loop; closed_loop.launch.xml composes it by default)',
        'stream_thread': 'each estimate is one callback on the events executor',
    },
)


def build_config(values: dict) -> ControllerNodeConfig:
    """Validate raw parameter values (a missing name takes its default).

    Parameters
    ----------
    values : dict
        Parameter name to raw value.

    Raises
    ------
    ControllerParameterError
        Naming the first invalid parameter and its value.
    """
    v = PARAMETERS.validate(values)
    params, delay, enabled = (
        v.pop(name) for name in ('params', 'delay_commands', 'start_enabled')
    )
    period, trigger = v.pop('diagnostics_period'), v.pop('trigger')
    try:
        excitation = excitation_from_parameters(v)
        config = ControllerConfig.from_mapping(v)
        check_trigger(trigger, config.mode)
    except (LoopExcitationError, ControllerConfigError, ValueError) as err:
        raise ControllerParameterError(str(err)) from err
    return ControllerNodeConfig(params, config, delay, enabled, period, trigger, excitation)


class ControllerNode(Node):
    """The levitation controller (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    ControllerParameterError
        If a parameter is invalid (or the parameter set cannot be read).
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.config = cfg = build_config(PARAMETERS.declare(self))
        from maglev_ros.physics import make_model

        try:
            model = make_model(cfg.params)
            self.controller = controller = make_controller(model, cfg.controller)
        except (ValueError, OSError) as err:
            raise ControllerParameterError(f'params {cfg.params!r}: {err}') from err
        try:
            self.core = Commander(
                controller, model.n_outputs // 3, cfg.trigger, cfg.excitation, cfg.delay_commands
            )
        except (ValueError, LoopExcitationError) as err:
            raise ControllerParameterError(str(err)) from err
        controller.set_enabled(cfg.start_enabled)
        self._pub = self.create_publisher(JointState, COMMAND_TOPIC, LOCKSTEP_COMMAND_QOS)
        self._excitation_pub = None
        if self.core.excited:
            self._excitation_pub = self.create_publisher(
                JointState, EXCITATION_TOPIC, LOCKSTEP_COMMAND_QOS
            )
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        if cfg.trigger == 'estimate':
            self._estimates = self.create_subscription(
                Odometry, ESTIMATE_TOPIC, self._on_estimate_only, LATEST_QOS
            )
            self.create_timer(cfg.controller.input_timeout, self._check_stale)
        else:
            self.create_subscription(JointState, CURRENTS_TOPIC, self._on_currents, SENSOR_QOS)
            if self.core.lqr:
                self.create_subscription(Odometry, ESTIMATE_TOPIC, self._on_estimate, SENSOR_QOS)
            for k in range(0 if self.core.lqr else self.core.n_sensors):
                self.create_subscription(
                    MagneticField, field_topic(k), lambda m, k=k: self._on_field(k, m), SENSOR_QOS
                )
        self.create_subscription(PoseStamped, REFERENCE_TOPIC, self._on_reference, 10)
        self.create_service(SetBool, CONTROLLER_ENABLE_SERVICE, self._on_enable)
        self.create_timer(cfg.diagnostics_period, self.publish_diagnostics)
        self.get_logger().info(f'{cfg.controller.mode} on {cfg.params}, {self.core.describe()}')

    @property
    def commands(self) -> int:
        """Commands published."""
        return self.core.commands

    # ------------------------------------------------------------------ inputs
    def _publish(self, commands) -> None:
        for c in commands if isinstance(commands, list) else [commands]:
            if self._excitation_pub is not None:  # the excitation part, just before its command
                self._excitation_pub.publish(command_message(c.stamp_ns, c.excitation))
            self._pub.publish(command_message(c.stamp_ns, c.total))
            if c.status_changed:
                s = self.controller.status()
                if s.level == 'ERROR':
                    self.get_logger().warning(s.message)
                self.publish_diagnostics()  # an ERROR (stale input) is reported at once

    def _on_currents(self, msg: JointState) -> None:
        self.core.heard(self.get_clock().now().nanoseconds)
        if len(msg.effort) != self.core.n_inputs:
            text = f'expected {self.core.n_inputs} currents, got {list(msg.effort)}'
            return self.get_logger().error(f'{CURRENTS_TOPIC}: {text}', throttle_duration_sec=1.0)
        self._publish(self.core.sample_part(self.core.currents_part, stamp_ns(msg), msg.effort))

    def _on_estimate(self, msg: Odometry) -> None:
        self._publish(self.core.sample_part(1, stamp_ns(msg), odometry_state(msg)))

    def _on_field(self, k: int, msg: MagneticField) -> None:
        f = msg.magnetic_field
        self._publish(self.core.sample_part(k, stamp_ns(msg), (f.x, f.y, f.z)))

    def _on_estimate_only(self, msg: Odometry) -> None:
        self.core.heard(self.get_clock().now().nanoseconds)
        self._publish(self.core.estimate(stamp_ns(msg), odometry_state(msg), time.monotonic()))

    def _check_stale(self) -> None:
        if self.context.ok():
            heard = self._estimates.get_publisher_count() > 0
            command = self.core.check_stale(time.monotonic(), heard)
            if command is not None:
                self._publish(command)

    def _on_reference(self, msg: PoseStamped) -> None:
        p = msg.pose.position
        ok, text = self.core.set_reference(msg.header.frame_id, (p.x, p.y, p.z))
        (self.get_logger().info if ok else self.get_logger().error)(text)

    def _on_enable(self, request, response):
        """Switch the controller; the response names the first command it governs."""
        response.success = True
        response.message = self.core.enable(bool(request.data))
        self.get_logger().info(f'controller {response.message}')
        self.publish_diagnostics()
        return response

    def publish_diagnostics(self) -> None:
        """Publish the controller's level, message, timeouts and saturations."""
        if not self.context.ok():
            return
        now_ns = self.get_clock().now().nanoseconds
        level, message, values = self.core.diagnostic(now_ns, self.config.diagnostics_period)
        self._diag_pub.publish(
            diagnostic_array(now_ns, f'{NODE_NAME}: levitation', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Run the controller until SIGINT or SIGTERM; exit status 0, or 2 for bad parameters.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).
    """
    return run_nodes([ControllerNode], args, NODE_NAME, (ControllerParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
