"""Online identifier node: ``ros2 run maglev_ros identifier``.

Recursive ARX on channels written in the bag converter's syntax (``TOPIC:PATH``
and linear combinations such as ``ux=0.5*maglev/currents:effort[0]-0.5*...``):
SISO, MISO, or one MISO row per output. The core is
:class:`maglev_ros.bags.online_identification.OnlineIdentification`: it says
when a sample is complete (stamps of the fields and currents; commands held),
which samples the window ``identify_from`` .. ``identify_until`` (settable at
run time) lets through, and what ``complete_on_next`` changes. A command
channel may say ``data[i]`` (the old Float64MultiArray commands) or
``effort[i]`` (JointState): either reads either.

At ``publish_rate`` (Hz, the node's clock) it publishes, Float64MultiArray each:
``maglev/identifier/model`` (``layout.dim[0]`` is ``theta``, each further
dimension one polynomial block, label ``A[y,y] na=2`` or ``B[y,u] nb=3 nk=1``,
``stride`` its offset: :func:`maglev_ros.sysid.online.coefficient_layout`),
``maglev/identifier/prediction_error`` (the last a-priori one-step error per
output, NaN while a row waits for its history) and ``maglev/identifier/fit``
(percent over ``fit_window`` samples), and on ``/diagnostics`` the samples,
covariance trace, drift and the counts of dropped or left-out samples. Nothing
is published before the first complete sample. The service
``maglev/identifier/reset`` (std_srvs/Trigger) restarts the estimate and says
how many samples it discarded.
"""

from __future__ import annotations

import importlib

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from maglev_ros.bags.errors import BagError
from maglev_ros.bags.online_identification import (
    IdentificationConfigError,
    OnlineIdentification,
    OnlineIdentificationConfig,
)
from maglev_ros.bags.online_identification import message_type_of as _message_type_of
from maglev_ros.nodes.messages import diagnostic_array
from maglev_ros.nodes.params import NodeParameterError, ParameterTable, config_params
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS, LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.sysid.online import load_kernels
from maglev_ros.topics import (
    DIAGNOSTICS_TOPIC,
    IDENTIFIER_FIT_TOPIC,
    IDENTIFIER_MODEL_TOPIC,
    IDENTIFIER_PREDICTION_ERROR_TOPIC,
    IDENTIFIER_RESET_SERVICE,
)

__all__ = [
    'PARAMETERS',
    'REMOVED',
    'IdentifierConfig',
    'IdentifierNode',
    'IdentifierParameterError',
    'build_config',
    'build_identifier',
    'main',
    'message_type_of',
]

NODE_NAME = 'maglev_identifier'
#: Parameters the identifier no longer has, and what replaced them.
REMOVED = {
    'intra_process': 'the identifier subscribes to every topic; a composed loop process '
    'publishes its topics for it (or runs the online identifier as a loop observer)',
}
IdentifierConfig = OnlineIdentificationConfig  # the validated parameters


class IdentifierParameterError(NodeParameterError):
    """An identifier parameter has an invalid value."""


PARAMETERS = ParameterTable(
    NODE_NAME, IdentifierParameterError, config_params(IdentifierConfig), removed=REMOVED
)


def build_config(values: dict) -> IdentifierConfig:
    """Validate raw parameter values.

    Parameters
    ----------
    values : dict
        Parameter name to value (a missing name takes its default).

    Raises
    ------
    IdentifierParameterError
        Naming the first invalid parameter and its value.
    """
    try:
        return IdentifierConfig(**PARAMETERS.validate(values))
    except IdentificationConfigError as err:
        raise IdentifierParameterError(str(err)) from err


def build_identifier(cfg: IdentifierConfig) -> OnlineIdentification:
    """Build the ROS-free core of a configuration (channel or order errors as parameter errors).

    Parameters
    ----------
    cfg : IdentifierConfig
        Validated parameters.
    """
    try:
        return OnlineIdentification(cfg)
    except (BagError, ValueError) as err:
        raise IdentifierParameterError(f'identifier channels/orders: {err}') from err


def message_type_of(topic: str) -> str:
    """Message type (``pkg/msg/Type``) of a contract topic (parameter error if unknown).

    Parameters
    ----------
    topic : str
        Topic name, with or without the leading ``/``.
    """
    try:
        return _message_type_of(topic)
    except BagError as err:
        raise IdentifierParameterError(str(err)) from err


def _message_class(kind: str) -> type:
    package, _, name = kind.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def _array(data, dims=()) -> Float64MultiArray:
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=name, size=n, stride=k) for name, n, k in dims]
    msg.data = [float(v) for v in data]
    return msg


class IdentifierNode(Node):
    """The online identifier (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    IdentifierParameterError
        If a parameter is invalid.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.config = build_config(PARAMETERS.declare(self))
        self.core = core = build_identifier(self.config)
        self.add_on_set_parameters_callback(PARAMETERS.on_set(self, self._rebuild))
        load_kernels()  # now, not with the first sample
        for topic, kind in core.types.items():
            self.create_subscription(
                _message_class(kind),
                topic.lstrip('/'),  # relative: resolves in the node's namespace
                lambda msg, topic=topic: core.add(topic, msg),
                SENSOR_QOS if topic in core.stamped else LOCKSTEP_COMMAND_QOS,
            )
        self._model_pub = self.create_publisher(Float64MultiArray, IDENTIFIER_MODEL_TOPIC, 10)
        self._error_pub = self.create_publisher(
            Float64MultiArray, IDENTIFIER_PREDICTION_ERROR_TOPIC, 10
        )
        self._fit_pub = self.create_publisher(Float64MultiArray, IDENTIFIER_FIT_TOPIC, 10)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        self.create_service(Trigger, IDENTIFIER_RESET_SERVICE, self._on_reset)
        self.create_timer(1.0 / self.config.publish_rate, self.publish)
        self.get_logger().info(core.describe())

    def _rebuild(self, values: dict) -> IdentifierConfig:
        """Check the parameters with a change (the window), move the core's window to it."""
        config = build_config(values)
        self.core.set_window(*config.window_ns)
        return config  # stored as self.config by the parameter table

    samples = property(lambda self: self.core.samples, doc='Samples given to the ARX.')
    outside = property(lambda self: self.core.outside, doc='Samples left out by the window.')
    aligner = property(lambda self: self.core.aligner, doc='The stamp aligner of the core.')
    identifier = property(lambda self: self.core.identifier, doc='The recursive ARX.')

    def _on_reset(self, _request, response):
        response.success = True
        response.message = f'estimate reset; {self.core.reset()} samples discarded'
        self.get_logger().info(response.message)
        return response

    def publish(self) -> None:
        """Publish the model, the prediction error, the fit and the diagnostics."""
        if not self.context.ok():
            return
        report = self.core.report()
        if report.layout is not None:
            self._model_pub.publish(_array(report.layout.data, report.layout.dims))
            dims = [(name, 1, 1) for name in report.outputs]
            self._error_pub.publish(_array(report.status.prediction_error, dims))
            self._fit_pub.publish(_array(report.status.fit, dims))
        now_ns = self.get_clock().now().nanoseconds
        name = f'{NODE_NAME}: recursive ARX'
        self._diag_pub.publish(
            diagnostic_array(now_ns, name, report.level, report.message, report.values)
        )


def main(args: list[str] | None = None) -> int:
    """Run the identifier until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS ones included); exit status 2 for bad parameters.
    """
    return run_nodes([IdentifierNode], args, NODE_NAME, (IdentifierParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
