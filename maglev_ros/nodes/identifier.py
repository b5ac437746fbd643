"""Online identifier node: ``ros2 run maglev_ros identifier``.

Recursive ARX (:class:`maglev_ros.bags.live.ChannelIdentifier` around
:class:`maglev_ros.sysid.online.OnlineArx`, the update of
``sysid.RecursiveArx``) on channels written in the bag converter's syntax
(``TOPIC:PATH``, linear combinations such as
``ux=0.5*maglev/currents:effort[0]-0.5*maglev/currents:effort[1]``): SISO with
one output and one input, MISO with several inputs (several outputs give one
MISO row each, as batch ARX).

Sample completeness. A sample is complete when every stamped topic the
channels read (fields, currents, states: messages with a header) has delivered
its message of one stamp (:class:`~maglev_ros.bags.live.StampAligner`); the
sample is then evaluated with the trigger topic (default: the first input's)
last. Unstamped topics (``maglev/currents/command`` and other
``std_msgs`` arrays) are held at their latest value (zero-order hold), and
if the trigger itself is unstamped every trigger message completes a sample.
In a lockstep simulation the simulator publishes the fields and
``maglev/currents`` once per sample with the sample's stamp, so the identifier
sees exactly the samples a bag of the same run holds, paired as the bag
converter pairs them.

At ``publish_rate`` (Hz, the node's clock: simulated time under
``use_sim_time``) it publishes, std_msgs/Float64MultiArray each:

* ``maglev/identifier/model``: the coefficients; ``layout.dim[0]`` is
  ``theta`` (all of them), each further dimension one polynomial block
  (label ``A[y,y] na=2`` or ``B[y,u] nb=3 nk=1``, size, and in ``stride`` the
  offset of its first coefficient; ``A`` from lag 1, ``B`` from lag ``nk``),
  see :func:`maglev_ros.sysid.online.coefficient_layout`;
* ``maglev/identifier/prediction_error``: the last a-priori one-step
  prediction error ``y(t) - phi(t)^T theta(t-1)`` per output (output units;
  NaN while a row waits for its history);
* ``maglev/identifier/fit``: the fit of the one-step predictions over the last
  ``fit_window`` samples per output, percent;

and on ``/diagnostics`` (stamped with the node's clock) the samples, the
covariance trace, the parameter drift since the previous publication and the
counts of dropped or incomplete samples. Nothing is published before the
first complete sample.

Reset: the service ``maglev/identifier/reset`` (std_srvs/Trigger; Trigger
rather than Empty so the caller learns how many samples were discarded)
returns the estimate to ``theta = 0``, ``P = initial_covariance * I`` and
forgets the held and pending messages.
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from maglev_ros.bags.errors import BagError
from maglev_ros.bags.live import ChannelIdentifier, StampAligner
from maglev_ros.nodes.messages import diagnostic_array, stamp_ns
from maglev_ros.nodes.params import NodeParameterError, Param, ParameterTable, integer, number
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS, LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.topics import (
    DIAGNOSTICS_TOPIC,
    FIELD_MESSAGE_TYPE,
    IDENTIFIER_FIT_TOPIC,
    IDENTIFIER_MODEL_TOPIC,
    IDENTIFIER_PREDICTION_ERROR_TOPIC,
    IDENTIFIER_RESET_SERVICE,
    MESSAGE_TYPES,
    current_channel,
    field_channel,
    field_topic,
)

__all__ = [
    'PARAMETERS',
    'IdentifierConfig',
    'IdentifierNode',
    'IdentifierParameterError',
    'build_config',
    'main',
    'message_type_of',
]

NODE_NAME = 'maglev_identifier'
_FIELD_TOPIC = re.compile('^' + re.escape(field_topic(0)).replace('0', r'\d+') + '$')


class IdentifierParameterError(NodeParameterError):
    """An identifier parameter has an invalid value."""


@dataclass(frozen=True)
class IdentifierConfig:
    """Validated identifier parameters.

    Attributes
    ----------
    outputs, inputs : tuple of str
        Channel specs (the bag converter's syntax).
    na : tuple of int
        One order for all, or ny*ny values row by row.
    nb, nk : tuple of int
        One value for all, or ny*nu values row by row (samples).
    forgetting : float
        Forgetting factor in (0, 1].
    initial_covariance : float
        ``p0`` of ``P0 = p0 I``.
    window : int
        Sliding-window length, samples (0: none).
    fit_window : int
        Samples of the prediction-fit window.
    wait_for_history : bool
        Update a row only once its regressor is complete (as batch ARX).
    trigger : str
        Topic completing a sample ('' : the first input's topic).
    publish_rate : float
        Publications per second of the node's clock, Hz.
    """

    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    na: tuple[int, ...]
    nb: tuple[int, ...]
    nk: tuple[int, ...]
    forgetting: float
    initial_covariance: float
    window: int
    fit_window: int
    wait_for_history: bool
    trigger: str
    publish_rate: float


def _channels(name: str, specs: tuple[str, ...]) -> tuple[str, ...]:
    if not specs or any(not s.strip() for s in specs):
        raise IdentifierParameterError(
            f'{name} must be a non-empty list of channel specs TOPIC:FIELD, got {list(specs)}'
        )
    return specs


def _orders(name: str, values: tuple[int, ...]) -> tuple[int, ...]:
    if not values or any(v < 0 for v in values):
        raise IdentifierParameterError(
            f'{name} must be a non-empty list of integers >= 0, got {list(values)}'
        )
    return values


_INPUT_UX = f'ux=0.5*{current_channel(0)}-0.5*{current_channel(1)}'

PARAMETERS = ParameterTable(
    NODE_NAME,
    IdentifierParameterError,
    {
        'outputs': Param(
            [field_channel(0, 'x')], 'output channels (bag converter syntax)', check=_channels
        ),
        'inputs': Param([_INPUT_UX], 'input channels (bag converter syntax)', check=_channels),
        'na': Param([2], 'orders of A: one for all, or ny*ny row by row', check=_orders),
        'nb': Param([2], 'numbers of B coefficients: one, or ny*nu row by row', check=_orders),
        'nk': Param([1], 'input delays, samples: one, or ny*nu row by row', check=_orders),
        'forgetting': Param(
            1.0,
            'forgetting factor (1: none, as MATLAB recursiveARX)',
            check=number(0, above=True, high=1),
        ),
        'initial_covariance': Param(
            1e4, 'P0 = initial_covariance * I (as MATLAB)', check=number(0, above=True)
        ),
        'window': Param(0, 'sliding window of the estimate, samples (0: none)', check=integer(0)),
        'fit_window': Param(1000, 'samples of the prediction-fit window', check=integer(2)),
        'wait_for_history': Param(
            True, 'update once the regressor is complete (as batch arx); false: zeros before'
        ),
        'trigger': Param('', "topic completing a sample ('': the first input's topic)"),
        'publish_rate': Param(
            10.0, 'model, error, fit and diagnostics per second, Hz', check=number(0, above=True)
        ),
    },
)


def _shaped(name: str, values: tuple[int, ...], rows: int, cols: int) -> object:
    if len(values) == 1:
        return values[0]
    if len(values) != rows * cols:
        raise IdentifierParameterError(
            f'{name} must have 1 or {rows}*{cols} = {rows * cols} values, got {list(values)}'
        )
    return np.array(values, dtype=int).reshape(rows, cols)


def build_config(values: dict) -> IdentifierConfig:
    """Validate raw parameter values.

    Parameters
    ----------
    values : dict
        Parameter name to value (a missing name takes its default).

    Returns
    -------
    IdentifierConfig

    Raises
    ------
    IdentifierParameterError
        Naming the first invalid parameter and its value.
    """
    return IdentifierConfig(**PARAMETERS.validate(values))


def build_identifier(cfg: IdentifierConfig) -> ChannelIdentifier:
    """Build the ROS-free identifier of a configuration.

    Parameters
    ----------
    cfg : IdentifierConfig
        Validated parameters.

    Returns
    -------
    ChannelIdentifier

    Raises
    ------
    IdentifierParameterError
        A bad channel spec, trigger or order combination.
    """
    ny, nu = len(cfg.outputs), len(cfg.inputs)
    try:
        return ChannelIdentifier(
            list(cfg.outputs),
            list(cfg.inputs),
            _shaped('na', cfg.na, ny, ny),
            _shaped('nb', cfg.nb, ny, nu),
            _shaped('nk', cfg.nk, ny, nu),
            trigger=cfg.trigger or None,
            forgetting=cfg.forgetting,
            initial_covariance=cfg.initial_covariance,
            window=cfg.window or None,
            fit_window=cfg.fit_window,
            wait_for_history=cfg.wait_for_history,
        )
    except IdentifierParameterError:
        raise
    except (BagError, ValueError) as err:
        raise IdentifierParameterError(f'identifier channels/orders: {err}') from None


def message_type_of(topic: str) -> str:
    """Message type (``pkg/msg/Type``) of a contract topic.

    Parameters
    ----------
    topic : str
        Topic name, with or without the leading ``/``.

    Returns
    -------
    str

    Raises
    ------
    IdentifierParameterError
        If the topic is not in the topic contract (``docs/topics.md``).
    """
    relative = topic.lstrip('/')
    if _FIELD_TOPIC.match(relative):
        return FIELD_MESSAGE_TYPE
    for name, kind in MESSAGE_TYPES.items():
        if name.lstrip('/') == relative:
            return kind
    raise IdentifierParameterError(
        f'channel topic {topic!r} is not in the topic contract (docs/topics.md); '
        f'known: {field_topic(0)} .., {", ".join(sorted(MESSAGE_TYPES))}'
    )


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
        self.config = cfg = build_config(PARAMETERS.declare(self))
        self.identifier = ident = build_identifier(cfg)
        kinds = {topic: message_type_of(topic) for topic in ident.topics}
        classes = {topic: _message_class(kind) for topic, kind in kinds.items()}
        stamped = {t for t, cls in classes.items() if hasattr(cls, 'header')}
        self.aligner = StampAligner(ident.topics, stamped, ident.sampler.trigger)
        self.rejected = 0  # samples the ARX refused (non-finite values)
        self.last_error: np.ndarray | None = None
        for topic, cls in classes.items():
            qos = SENSOR_QOS if topic in stamped else LOCKSTEP_COMMAND_QOS
            self.create_subscription(
                cls,
                topic.lstrip('/'),  # relative: resolves in the node's namespace
                lambda msg, topic=topic, stamped=topic in stamped: self._on_message(
                    topic, msg, stamped
                ),
                qos,
            )
        self._model_pub = self.create_publisher(Float64MultiArray, IDENTIFIER_MODEL_TOPIC, 10)
        self._error_pub = self.create_publisher(
            Float64MultiArray, IDENTIFIER_PREDICTION_ERROR_TOPIC, 10
        )
        self._fit_pub = self.create_publisher(Float64MultiArray, IDENTIFIER_FIT_TOPIC, 10)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        self.create_service(Trigger, IDENTIFIER_RESET_SERVICE, self._on_reset)
        self.create_timer(1.0 / cfg.publish_rate, self.publish)
        outs, ins = ident.sampler.names
        self.get_logger().info(
            f'recursive ARX {" ".join(outs)} <- {" ".join(ins)}, na {list(cfg.na)} nb '
            f'{list(cfg.nb)} nk {list(cfg.nk)}, forgetting {cfg.forgetting:g}, sample on '
            f'{ident.sampler.trigger} (stamped: {", ".join(sorted(stamped)) or "none"})'
        )

    @property
    def samples(self) -> int:
        """Samples given to the ARX since the start or the last reset."""
        return self.identifier.arx.samples

    def _on_message(self, topic: str, msg, stamped: bool) -> None:
        stamp = stamp_ns(msg) if stamped else None
        for name, message in self.aligner.add(topic, stamp, message=msg):
            try:
                error = self.identifier.add(name, message)
            except ValueError:
                self.rejected += 1
                continue
            if error is not None:
                self.last_error = error

    def _on_reset(self, _request, response):
        discarded = self.samples
        self.identifier.reset()
        self.aligner.reset()
        self.last_error = None
        response.success = True
        response.message = f'estimate reset; {discarded} samples discarded'
        self.get_logger().info(response.message)
        return response

    def publish(self) -> None:
        """Publish the model, the prediction error, the fit and the diagnostics."""
        if not self.context.ok():
            return
        status = self.identifier.status()
        counts = self.identifier.sampler.counts
        now_ns = self.get_clock().now().nanoseconds
        if status.samples:
            layout = self.identifier.layout()
            self._model_pub.publish(_array(layout.data, layout.dims))
            outs = self.identifier.sampler.names[0]
            dims = [(name, 1, 1) for name in outs]
            self._error_pub.publish(_array(status.prediction_error, dims))
            self._fit_pub.publish(_array(status.fit, dims))
        if status.samples == 0:
            level, message = DiagnosticStatus.OK, 'waiting for complete samples'
        elif not np.all(np.isfinite(status.theta)):
            level, message = DiagnosticStatus.ERROR, 'estimate not finite: reset it'
        else:
            level, message = DiagnosticStatus.OK, 'estimating'
        values = {
            'samples': status.samples,
            'covariance trace': f'{status.covariance_trace:.9g}',
            'parameter drift': f'{status.drift:.9g}',
            'relative parameter drift': f'{status.relative_drift:.9g}',
            'fit (%)': ' '.join(f'{f:.3f}' for f in status.fit),
            'incomplete stamps dropped': self.aligner.dropped,
            'samples with held values': counts.held,
            'messages without the field': counts.bad,
            'samples rejected': self.rejected,
        }
        self._diag_pub.publish(
            diagnostic_array(now_ns, f'{NODE_NAME}: recursive ARX', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Run the identifier until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return run_nodes([IdentifierNode], args, NODE_NAME, (IdentifierParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
