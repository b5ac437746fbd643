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
converter pairs them. ``complete_on_next`` (default false; with a stamped
trigger) holds a completed sample until the first message of the next stamp,
so the unstamped messages that arrive in between (the command that answers
it) are its input: the pairing of a real-time simulator, which publishes a
burst of samples and then gets the one command computed from them, the
command that the bag converter pairs with the burst's last sample by its log
time (see :class:`~maglev_ros.bags.live.StampAligner`).

Window. ``identify_from`` (s of sample stamps, default 0: from the first)
and ``identify_until`` (s, default 0: no end; else ``>= identify_from``)
bound the samples given to the ARX: a sample whose stamp (its stamped set's;
with an unstamped trigger the newest stamp released, the window not applying
before any) is before ``identify_from`` or after ``identify_until`` is left
out (counted in the diagnostics), but its messages are still held, so the
first sample inside the window has its held input: an estimate of exactly
the samples in between, from subscriptions matched long before and a
simulation that runs on (as the recorder's ``record_from`` and
``record_until``).

Composed (``intra_process: true``, in one process with the simulator and the
controller): a topic that a node of this process publishes is taken from its
:func:`~maglev_ros.nodes.intra_process.tap` (the bytes the publisher
serialised, deserialised here in the publisher's thread) instead of a
subscription; messages of other processes on such a topic are then not
taken. The other topics are subscribed as usual.

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
import threading
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from maglev_ros.bags.errors import BagError
from maglev_ros.bags.live import ChannelIdentifier, StampAligner
from maglev_ros.cdr.reader import RawFieldReader
from maglev_ros.cdr.templates import HEADER_STAMP
from maglev_ros.nodes import intra_process
from maglev_ros.nodes.messages import diagnostic_array, stamp_ns
from maglev_ros.nodes.params import NodeParameterError, Param, ParameterTable, integer, number
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS, LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.sysid.online import load_kernels
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
    complete_on_next : bool
        Release a completed stamp's sample at the next stamp's first message.
    identify_from : float
        Sample stamp from which samples reach the ARX, s (0: all).
    identify_until : float
        Sample stamp after which samples do not reach the ARX, s (0: no end).
    intra_process : bool
        Take the topics published in this process from their taps.
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
    complete_on_next: bool = False
    identify_from: float = 0.0
    identify_until: float = 0.0
    intra_process: bool = False


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
        'complete_on_next': Param(
            False,
            "release a stamp's sample at the next stamp's first message, so the unstamped "
            'messages (commands) in between are its input (stamped trigger; real-time bursts)',
        ),
        'identify_from': Param(
            0.0,
            'sample stamp from which samples are given to the ARX, s (0: all; earlier '
            'samples still set the held values)',
            check=number(0),
            mutable=True,
        ),
        'identify_until': Param(
            0.0,
            'sample stamp after which samples are not given to the ARX, s (0: no end)',
            check=number(0),
            mutable=True,
        ),
        'intra_process': Param(
            False,
            'take the topics that nodes of this process publish from them directly, not '
            'through the middleware (composed real-time loops)',
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
    v = PARAMETERS.validate(values)
    if v['identify_until'] and v['identify_until'] < v['identify_from']:
        raise IdentifierParameterError(
            f'identify_until must be 0 (no end) or >= identify_from {v["identify_from"]:g}, '
            f'got {v["identify_until"]:g}'
        )
    return IdentifierConfig(**v)


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
        # the window may move at run time (a lab sets it once the settling is over)
        self.add_on_set_parameters_callback(PARAMETERS.on_set(self, build_config))
        self.identifier = ident = build_identifier(cfg)
        load_kernels()  # now, not with the first sample in a publisher's real-time thread
        kinds = {topic: message_type_of(topic) for topic in ident.topics}
        classes = {topic: _message_class(kind) for topic, kind in kinds.items()}
        stamped = {t for t, cls in classes.items() if hasattr(cls, 'header')}
        self.aligner = StampAligner(
            ident.topics, stamped, ident.sampler.trigger, complete_on_next=cfg.complete_on_next
        )
        self.rejected = 0  # samples the ARX refused (non-finite values)
        self.outside = 0  # samples outside identify_from .. identify_until
        self.last_error: np.ndarray | None = None
        self._stamp: int | None = None  # stamp of the newest stamped message released
        # taps deliver in their publishers' threads, the executor runs the rest
        self._lock = threading.Lock()
        self._taps: list[tuple[intra_process.MessageTap, object]] = []
        for topic, cls in classes.items():
            is_stamped = topic in stamped
            tap = None
            if cfg.intra_process:
                tap = intra_process.tap(self.context, self.resolve_topic_name(topic.lstrip('/')))
            if tap is not None and tap.publishers > 0:
                listener = self._tap_listener(topic, cls, is_stamped)
                tap.connect(listener, NODE_NAME)
                self._taps.append((tap, listener))
                self.get_logger().info(f'{topic}: taken in this process (intra_process)')
                continue
            qos = SENSOR_QOS if is_stamped else LOCKSTEP_COMMAND_QOS
            self.create_subscription(
                cls,
                topic.lstrip('/'),  # relative: resolves in the node's namespace
                lambda msg, topic=topic, stamped=is_stamped: self._on_message(topic, msg, stamped),
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
    def config(self) -> IdentifierConfig:
        """The validated parameters (the window may be set at run time)."""
        return self._config

    @config.setter
    def config(self, config: IdentifierConfig) -> None:
        """Store a validated configuration and its window.

        Parameters
        ----------
        config : IdentifierConfig
            The validated parameters.
        """
        self._config = config
        # sample stamps, ns: first and last identified (last None: no end)
        self._window = (
            round(config.identify_from * 1e9),
            round(config.identify_until * 1e9) or None,
        )

    @property
    def samples(self) -> int:
        """Samples given to the ARX since the start or the last reset."""
        return self.identifier.arx.samples

    def _tap_listener(self, topic: str, cls: type, stamped: bool):
        """Return a tap listener: a publisher's list of CDR messages, handled in order.

        The channels' fields and the stamp are read from the bytes
        (:class:`~maglev_ros.cdr.reader.RawFieldReader`: a few us, where rclpy's
        deserialisation costs about 20 us a message); a message it cannot lay
        out is deserialised.
        """
        reader = RawFieldReader(
            message_type_of(topic),
            self.identifier.sampler.field_paths(topic),
            HEADER_STAMP if stamped else None,
        )

        def on_messages(messages: list) -> None:
            decoded = []
            for data in messages:
                read = reader.read(data)
                if read is None:  # another layout than the reader's: the message itself
                    msg = deserialize_message(data, cls)
                    read = (stamp_ns(msg) if stamped else None, msg)
                decoded.append(read)
            samples: list = []
            with self._lock:
                # a publisher hands over a whole read per topic (a board's may be long):
                # its stamps wait for the other topics' messages, none is dropped
                self.aligner.depth = max(self.aligner.depth, len(decoded) + 1)
                for stamp, payload in decoded:
                    self._handle(topic, stamp, payload, samples)
                self._identify(samples)

        return on_messages

    def _on_message(self, topic: str, msg, stamped: bool) -> None:
        samples: list = []
        with self._lock:
            self._handle(topic, stamp_ns(msg) if stamped else None, msg, samples)
            self._identify(samples)

    def _identify(self, samples: list) -> None:
        """Give the ARX the samples of one message or burst, in order (the caller holds the lock).

        One compiled call for them all (``OnlineArx.update_many``); if one is
        refused (not finite) they are given one at a time, the refused counted.
        """
        if not samples:
            return
        arx = self.identifier.arx
        try:
            errors = arx.update_many(
                np.array([y for y, _ in samples]), np.array([u for _, u in samples])
            )
        except ValueError:
            for y, u in samples:
                try:
                    self.last_error = arx.update(y, u)
                except ValueError:
                    self.rejected += 1
            return
        self.last_error = errors[-1]

    def _handle(self, topic: str, stamp: int | None, payload, samples: list) -> None:
        """Align and sample one message; append the samples it completes (caller holds the lock).

        ``payload`` is the message, or the tuple of its field values
        (:meth:`ChannelSampler.field_paths` order); ``samples`` gets each
        completed sample inside the window as ``(y, u)``.
        """
        sampler = self.identifier.sampler
        for name, (released_stamp, item) in self.aligner.add(topic, stamp, (stamp, payload)):
            if name in self.aligner.stamped:
                self._stamp = released_stamp
            if isinstance(item, tuple):
                sample = sampler.add_values(name, item)
            else:
                sample = sampler.add(name, item)
            if sample is None:
                continue
            first, last = self._window
            if self._stamp is not None and (
                self._stamp < first or (last is not None and self._stamp > last)
            ):
                self.outside += 1  # its values stay held: the next sample's regressor
                continue
            samples.append(sample)

    def _on_reset(self, _request, response):
        with self._lock:
            discarded = self.samples
            self.identifier.reset()
            self.aligner.reset()
            self.last_error = None
            self._stamp = None
        response.success = True
        response.message = f'estimate reset; {discarded} samples discarded'
        self.get_logger().info(response.message)
        return response

    def publish(self) -> None:
        """Publish the model, the prediction error, the fit and the diagnostics."""
        if not self.context.ok():
            return
        with self._lock:  # a consistent snapshot; published without the lock
            status = self.identifier.status()
            counts = self.identifier.sampler.counts
            layout = self.identifier.layout() if status.samples else None
            dropped, outside, rejected = self.aligner.dropped, self.outside, self.rejected
        now_ns = self.get_clock().now().nanoseconds
        if layout is not None:
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
            'incomplete stamps dropped': dropped,
            'samples with held values': counts.held,
            'messages without the field': counts.bad,
            'samples rejected': rejected,
            'samples outside the window': outside,
        }
        self._diag_pub.publish(
            diagnostic_array(now_ns, f'{NODE_NAME}: recursive ARX', level, message, values)
        )

    def destroy_node(self) -> None:
        """Disconnect from the taps, then destroy the node."""
        for tap, listener in self._taps:
            tap.disconnect(listener)
        self._taps = []
        super().destroy_node()


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
