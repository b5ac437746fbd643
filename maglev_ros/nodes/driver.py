"""Board driver node: ``ros2 run maglev_ros driver``.

Talks to a Maggy board (or ``maglev-virtual-board``) over a serial port and
publishes on the shared topics (``docs/topics.md``), like the simulator node:
``maglev/sensor_<k>/field`` (MagneticField, T; V2x the raw fields, V4x the
board's processed ones), ``maglev/currents`` (JointState, effort A; V2x the
currents of the applied PWM, V4x the measured ones) and ``/diagnostics``. It
takes ``maglev/currents/command`` (JointState, effort A, names checked when
given) and the service ``maglev/enable`` (std_srvs/SetBool).

Everything between the port and the topics is the ROS-free
:class:`~maglev_ros.hardware.board_session.BoardSession` (the link thread,
decoding and stamps, the command guard, the command timeout, zero currents on
shutdown); this node declares its parameters, publishes the samples the session
queued at every tick (1 ms, or ``read_interval``), and hands it commands, the
enable state and the timeout check. Behaviour, latency and QoS:
``docs/boards.md``, "The driver node".
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState, MagneticField
from std_srvs.srv import SetBool

from maglev_ros import topics
from maglev_ros.cdr.batch import sensor_sample_serialiser
from maglev_ros.hardware.board_session import BoardSession
from maglev_ros.hardware.driver_config import (
    DriverConfig,
    DriverConfigError,
    DriverSettings,
    driver_config,
)
from maglev_ros.hardware.serial_link import LinkError
from maglev_ros.hardware.v2x_stream import DecoderStats
from maglev_ros.nodes.contract import COMMAND_QOS, DIAGNOSTICS_QOS, SENSOR_QOS, run_nodes
from maglev_ros.nodes.messages import CommandMessageError, command_currents, diagnostic_array
from maglev_ros.nodes.params import NodeParameterError, ParameterTable, config_params

__all__ = [
    'PARAMETERS',
    'BoardNotFoundError',
    'DriverConfig',
    'DriverNode',
    'DriverParameterError',
    'build_config',
    'main',
]

NODE_NAME = 'maglev_driver'
PUBLISH_PERIOD_S = 0.001  # s between publications (a V2x USB burst), or read_interval


class DriverParameterError(NodeParameterError):
    """A driver parameter has an invalid value."""


class BoardNotFoundError(DriverParameterError):
    """The port holds no board answering as the firmware parameter says (V4x PC control)."""


PARAMETERS = ParameterTable(
    NODE_NAME,
    DriverParameterError,
    config_params(DriverSettings),  # each setting declared once, in the ROS-free core
    removed={
        'intra_process': 'a loop process runs the board in-process (maglev_ros.loop); '
        'this node always publishes on the topics',
    },
)
_PARAMETERS = PARAMETERS  # the name test_launch and older callers use


def build_config(values: dict) -> DriverConfig:
    """Validate raw parameter values (a missing one takes its default) into a ``DriverConfig``.

    Parameters
    ----------
    values : dict
        Parameter name to raw value (the same rules at start-up and at run time).

    Raises
    ------
    DriverParameterError
        Naming the first invalid parameter and its value.
    """
    try:
        return driver_config(PARAMETERS.validate(values))
    except DriverConfigError as err:
        raise DriverParameterError(str(err)) from None


class DriverNode(Node):
    """The board driver: ROS wiring around a :class:`BoardSession` (module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``, ``parameter_overrides``).

    Raises
    ------
    DriverParameterError
        If a parameter is invalid; :class:`BoardNotFoundError` if a V4x
        PC-control board does not answer on the port.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.session: BoardSession | None = None
        self.config = cfg = build_config(PARAMETERS.declare(self))
        self.add_on_set_parameters_callback(PARAMETERS.on_set(self, build_config))
        self.session = BoardSession(cfg, self.get_logger())
        self.stream = self.session.stream
        pubs = [
            self.create_publisher(MagneticField, topics.field_topic(k), SENSOR_QOS)
            for k in range(cfg.n_sensors)
        ]
        pubs.append(self.create_publisher(JointState, topics.CURRENTS_TOPIC, SENSOR_QOS))
        # per sample: the field of each sensor, then the currents (the serialiser's order)
        self._publish_raw = [pub.handle.publish_raw for pub in pubs]
        self._serialiser = sensor_sample_serialiser(cfg.sensor_frames)  # compiled now
        self._diag_pub = self.create_publisher(
            DiagnosticArray, topics.DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS
        )
        self.create_subscription(JointState, topics.COMMAND_TOPIC, self._on_command, COMMAND_QOS)
        self.create_service(SetBool, topics.ENABLE_SERVICE, self._on_enable)
        self.create_timer(max(PUBLISH_PERIOD_S, cfg.read_interval), self._on_tick)
        self.create_timer(min(0.02, cfg.command_timeout / 4), self.session.check_timeout)
        self.create_timer(cfg.diagnostics_period, self._publish_diagnostics)
        try:
            self.session.open()
        except LinkError as err:  # a board that is not there is a wrong parameter
            raise BoardNotFoundError(f'{err} (parameters port, firmware)') from None
        self.get_logger().info(self.session.describe())

    @property
    def config(self) -> DriverConfig:
        """The validated parameters (run-time changes reach the session's command guard)."""
        return self._config

    @config.setter
    def config(self, config: DriverConfig) -> None:
        """Store validated parameters; the limit and timeout reach the guard.

        Parameters
        ----------
        config : DriverConfig
            The validated parameters.
        """
        self._config = config
        if self.session is not None:
            self.session.configure(config)

    @property
    def counters(self) -> dict[str, int]:
        """Records, commands sent/rejected/clamped/unsent/ignored, timeouts, link events."""
        return self.session.counters

    @property
    def link_state(self) -> str:
        """``connecting``, ``waiting for board``, ``connected`` or ``disconnected``."""
        return self.session.link.state

    @property
    def last_info(self) -> str:
        """Text of the board's last info line (V4x), or the last link error (V4x PC)."""
        return self.session.link.last_info

    @property
    def decoder_stats(self) -> DecoderStats:
        """Counters of the record decoder of the current connection (V2x)."""
        return self.session.stream.decoder_stats

    @property
    def enabled(self) -> bool:
        """Whether commands are applied (else zero currents are sent)."""
        return self.session.enabled

    def _on_command(self, msg: JointState) -> None:
        try:
            self.session.command(command_currents(msg))
        except CommandMessageError as err:  # the message, not its values: rejected, counted
            self.session.reject(str(err))

    def _on_enable(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self.session.set_enabled(request.data)
        response.success = True
        response.message = 'enabled' if self.enabled else 'disabled: zero currents sent'
        self.get_logger().info(f'driver {response.message}')
        return response

    def _on_tick(self) -> None:
        """Publish the samples the board gave since the last tick, each sensor then currents."""
        block = self.session.take()
        if block is not None:
            messages = self._serialiser.serialise(block.stamps_ns, block.values)
            for publish, message in zip(self._publish_raw * len(block), messages, strict=True):
                publish(message)

    def _publish_diagnostics(self) -> None:
        h, now = self.session.report(), self.get_clock().now().nanoseconds
        name, port = f'{NODE_NAME}: board link', self.config.port
        self._diag_pub.publish(diagnostic_array(now, name, h.level, h.message, h.values, port))

    def destroy_node(self) -> None:
        """Close the board (link thread stopped, zero currents, port closed), then the node."""
        self.session.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the driver until SIGINT, SIGTERM or SIGHUP; exit status 0, or 2 for bad parameters.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included; None: ``sys.argv``).
    """
    return run_nodes([DriverNode], args, NODE_NAME, (DriverParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
