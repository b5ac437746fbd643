"""Levitation controller node: ``ros2 run maglev_ros controller``.

Runs the ROS-free controller of :mod:`maglev_ros.control` (``mode``: ``lqr``
state feedback on ``maglev/state/estimate``, or ``pd``, the firmware's PD on
the raw fields; every setting of
:class:`~maglev_ros.control.ControllerConfig` is a parameter, defaults as
``config/controller.yaml``) and publishes ``maglev/currents/command``
(std_msgs/Float64MultiArray, 4 currents in A, x+ x- y+ y-, clipped at
``current_limit``).

One command per sample (the lockstep contract of
:mod:`maglev_ros.physics.session`):

* LQR: a sample is its ``maglev/currents`` (published by the simulator or
  the driver) and its estimate (``maglev/state/estimate``, same stamp); they
  are handled in any order. The command is computed once both arrived, with
  the estimate and the measured currents of that stamp. A sample whose
  estimate never comes -- an estimate of a later stamp arrived, or currents
  more than ``input_timeout`` s (of stamps) later did -- gets the core's
  answer to a missing estimate: the last command held, and once no estimate
  came for ``input_timeout`` zero currents;
* PD: a sample is the field of every sensor and the currents, handled in any
  order; one command once it is complete (or a part is known lost, as for
  the estimator, :mod:`maglev_ros.nodes.sample_assembly`).

Samples are answered in stamp order, exactly one command each, never
depending on the order the callbacks ran in.

The lockstep simulator applies the command of sample k over k -> k+1; the
board applies it about one sample later, and the LQR's ``command_delay: 1``
designs for that. ``delay_commands: true`` (the simulation launch file sets
it) publishes for sample k the command computed at k - 1, so a lockstep
graph has the board's timing and steps exactly as
:class:`~maglev_ros.control.ClosedLoop` with ``command_delay`` 1.

Safety. Stale input (no estimate / sample for ``input_timeout``): zero
currents and an ERROR on ``/diagnostics`` at once. The controller re-arms by
itself once ``rearm_samples`` fresh inputs arrived in a row (integrators and
pending command cleared), as :class:`~maglev_ros.control.Watchdog` does. A
graph that stops completely (no sample at all) gets no more commands: the
board driver's own ``command_timeout`` zeroes the coils, and the
diagnostics (every ``diagnostics_period`` s of the node's clock) report
ERROR. ``start_enabled`` (default true) and the service
``maglev/controller/enable`` (std_srvs/SetBool) switch the controller; while
disabled it commands zero currents. The response says from which command
on (numbered from 0, the diagnostics' ``commands``) the new state holds:
after a disable that command and all later ones are zero, including one held
back by ``delay_commands``. ``maglev/reference``
(geometry_msgs/PoseStamped, frame ``maglev_base`` or empty) moves the
set-point (LQR); a bad one is refused with an error log.

Excitation (closed-loop identification, :mod:`maglev_ros.control.excitation`).
``excitation_signal`` (``none`` by default; ``prbs``, ``random_binary``,
``multisine``, ``chirp``) with ``excitation_amplitude``, ``_band``,
``_pattern``, ``_seed``, ``_length``, ``_cycles`` (the excitation node's
meanings) and ``excitation_start`` (s after the first sample) adds a known
signal to every command, as an input disturbance: it is then uncorrelated
with the sensor noise and is the instrument of IV. The value of sample k
(samples since the first, from the stamps) is the core's
:class:`~maglev_ros.control.excitation.ExcitationSchedule` value, as
:class:`~maglev_ros.control.ClosedLoop` adds it; nothing is added while the
controller commands zero. The node then publishes, per command and just
before it, the excitation part on ``maglev/currents/excitation``
(std_msgs/Float64MultiArray, 4 currents in A, x+ x- y+ y-; delayed with the
command by ``delay_commands``); ``maglev/currents/command`` carries the total.
Still exactly one command per sample.
"""

from __future__ import annotations

import struct
import threading
import time
from dataclasses import dataclass, fields

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool

from maglev_ros.cdr import ODOMETRY_VALUES
from maglev_ros.cdr.reader import RawFieldReader
from maglev_ros.cdr.templates import float_array_prefix
from maglev_ros.control import MODES, ControllerConfig, ControllerConfigError, make_controller
from maglev_ros.control.config import MAX_COMMAND_DELAY
from maglev_ros.control.excitation import (
    EXCITATION_SIGNALS,
    CommandExcitation,
    ExcitationSchedule,
    LoopExcitationError,
)
from maglev_ros.excitation import PATTERNS
from maglev_ros.nodes import intra_process
from maglev_ros.nodes.messages import diagnostic_array, stamp_ns
from maglev_ros.nodes.params import NodeParameterError, Param, ParameterTable, choice, number
from maglev_ros.nodes.params import integer as integer_rule
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS, LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.nodes.sample_assembly import SampleAssembler
from maglev_ros.nodes.sample_streams import Stream, open_streams
from maglev_ros.nodes.state_messages import odometry_state
from maglev_ros.physics.kernels import odometry_state_values
from maglev_ros.topics import (
    BASE_FRAME,
    COMMAND_TOPIC,
    CONTROLLER_ENABLE_SERVICE,
    CURRENTS_TOPIC,
    DIAGNOSTICS_TOPIC,
    ESTIMATE_TOPIC,
    EXCITATION_TOPIC,
    REFERENCE_TOPIC,
    field_topic,
)

__all__ = [
    'PARAMETERS',
    'ControllerNode',
    'ControllerNodeConfig',
    'ControllerParameterError',
    'build_config',
    'main',
]

NODE_NAME = 'maglev_controller'
#: s an estimator's publisher is matched before ``trigger: estimate`` says it is ready
READY_AFTER_S = 0.5
TRIGGERS = ('sample', 'estimate')
_DEFAULT = ControllerConfig()
_LEVELS = {
    'OK': DiagnosticStatus.OK,
    'WARN': DiagnosticStatus.WARN,
    'ERROR': DiagnosticStatus.ERROR,
}


class ControllerParameterError(NodeParameterError):
    """A controller parameter has an invalid value."""


@dataclass(frozen=True)
class ControllerNodeConfig:
    """Validated controller-node parameters.

    Attributes
    ----------
    params : str
        Parameter set the controller believes.
    controller : ControllerConfig
        The control law's settings.
    delay_commands : bool
        Publish the command of sample k - 1 for sample k (lockstep simulation).
    start_enabled : bool
        Enabled at start.
    diagnostics_period : float
        s of the node's clock between diagnostics.
    trigger : {'sample', 'estimate'}
        What a command answers: each sample (the lockstep contract) or each
        estimate message (real time at the estimator's ``publish_rate``).
    excitation : CommandExcitation
        The excitation added to the command (``signal`` ``none``: off).
    intra_process : bool
        ``trigger: estimate``: take the estimates from an estimator of this
        process and send the commands to its simulator directly
        (:mod:`~maglev_ros.nodes.intra_process`).
    stream_thread : bool
        ``trigger: estimate``: take the estimates in a thread of their own
        (:mod:`~maglev_ros.nodes.sample_streams`), answering the newest of
        each wake-up.
    """

    params: str
    controller: ControllerConfig
    delay_commands: bool
    start_enabled: bool
    diagnostics_period: float
    trigger: str = 'sample'
    excitation: CommandExcitation = CommandExcitation()
    intra_process: bool = False
    stream_thread: bool = True


def _parameter_set(name: str, value: str) -> str:
    if not value:
        raise ControllerParameterError(f'{name} must name a parameter set, got an empty string')
    return value


_DESCRIPTIONS = {
    'mode': ('lqr (state feedback on the estimate) or pd (firmware PD on the field)', None),
    'sample_rate': ('control rate, Hz (one command per sample)', number(0, above=True)),
    'command_delay': (
        f'samples before a command drives the coils (0 to {MAX_COMMAND_DELAY}; 1: the board; '
        'the LQR designs for it)',
        integer_rule(0, MAX_COMMAND_DELAY),
    ),
    'sensor_delay': ('samples of reading delay (0 or 1)', integer_rule(0, 1)),
    'coil_dynamics': ("LQR models the coils' L/R lag", None),
    'current_limit': ('largest command per coil, A', number(0, above=True)),
    'position_scale': ('Bryson scale of x y z, m', number(0, above=True)),
    'angle_scale': ('Bryson scale of alpha beta, rad', number(0, above=True)),
    'velocity_scale': ('Bryson scale of the velocity, m/s', number(0, above=True)),
    'rate_scale': ('Bryson scale of wx wy, rad/s', number(0, above=True)),
    'current_scale': ('Bryson scale of the commands, A', number(0, above=True)),
    'integral': ('integral action on x y z (anti-windup at the limit)', None),
    'integral_scale': ('Bryson scale of the integrated error, m s', number(0, above=True)),
    'input_timeout': ('s without input -> zero currents, ERROR', number(0, above=True)),
    'rearm_samples': ('fresh inputs in a row that re-arm after a timeout', integer_rule(1)),
    'pd_kp': ('PD proportional gain, A/T', number(0)),
    'pd_kd': ('PD derivative gain, A/(T/s)', number(0)),
    'pd_cutoff': ('PD field filter cut-off, Hz', number(0, above=True)),
    'pd_sensor': ('sensor the PD reads', integer_rule(0)),
    'pd_feedthrough': ("PD removes the coils' direct field", None),
    'magnet_threshold': ('PD active while |Bz - Bz without magnet| exceeds it, T', number(0)),
    'loss_distance': (
        'LQR: estimate this far from the equilibrium = magnet lost: zero currents, '
        'ERROR, latched until enabled again, m',
        number(0, above=True),
    ),
}

_EXCITATION_DEFAULT = CommandExcitation()
_EXCITATION_PARAMETERS = {
    'excitation_signal': Param(
        'none',
        f'excitation added to the command: {", ".join(EXCITATION_SIGNALS)} (published '
        f'apart on {EXCITATION_TOPIC})',
        check=choice(*EXCITATION_SIGNALS),
    ),
    'excitation_amplitude': Param(
        _EXCITATION_DEFAULT.amplitude, 'excitation: peak of each signal, A', check=number(0)
    ),
    'excitation_band': Param(
        list(_EXCITATION_DEFAULT.band), 'excitation: band (low, high), fractions of Nyquist'
    ),
    'excitation_pattern': Param(
        _EXCITATION_DEFAULT.pattern,
        'excitation: coil pattern (pairs: x+ = r_x, x- = -r_x, y+ = r_y, y- = -r_y)',
        check=choice(*PATTERNS),
    ),
    'excitation_seed': Param(0, 'excitation: seed of the signals', check=integer_rule(0)),
    'excitation_length': Param(
        _EXCITATION_DEFAULT.length, 'excitation: samples per period', check=integer_rule(1)
    ),
    'excitation_cycles': Param(0, 'excitation: periods (0: forever)', check=integer_rule(0)),
    'excitation_start': Param(
        0.0, 'excitation: s after the first sample it starts at', check=number(0)
    ),
}

PARAMETERS = ParameterTable(
    NODE_NAME,
    ControllerParameterError,
    {
        'params': Param(
            'maggy_v2', 'parameter set: maggy_v2, maggy_v4 or a YAML path', check=_parameter_set
        ),
        **{
            f.name: Param(
                getattr(_DEFAULT, f.name),
                _DESCRIPTIONS[f.name][0],
                check=choice(*MODES) if f.name == 'mode' else _DESCRIPTIONS[f.name][1],
            )
            for f in fields(ControllerConfig)
        },
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
        'stream_thread': Param(
            True,
            'trigger estimate: take the estimates in a thread of their own, the newest '
            'of each wake-up answered (older ones waiting are obsolete), not one '
            'executor callback each',
        ),
        'intra_process': Param(
            False,
            'trigger estimate, composed after the estimator and the simulator (same '
            'process): take the estimates and send the commands directly, in the '
            "simulator's thread (one burst of latency whatever the load; as rclcpp "
            'intra-process communication); the topics are still published',
        ),
        **_EXCITATION_PARAMETERS,
    },
)


_PARAMETERS = PARAMETERS  # the name test_launch uses


def build_config(values: dict) -> ControllerNodeConfig:
    """Validate raw parameter values.

    Parameters
    ----------
    values : dict
        Parameter name to value (a missing name takes its default).

    Returns
    -------
    ControllerNodeConfig

    Raises
    ------
    ControllerParameterError
        Naming the first invalid parameter and its value.
    """
    v = PARAMETERS.validate(values)
    params = v.pop('params')
    delay = v.pop('delay_commands')
    start_enabled = v.pop('start_enabled')
    period = v.pop('diagnostics_period')
    trigger = v.pop('trigger')
    intra = v.pop('intra_process')
    streams = v.pop('stream_thread')
    settings = {name[len('excitation_') :]: v.pop(name) for name in _EXCITATION_PARAMETERS}
    try:
        excitation = CommandExcitation(**settings)
    except LoopExcitationError as err:
        raise ControllerParameterError(f'excitation_{err}') from None
    try:
        config = ControllerConfig.from_mapping(v)
    except ControllerConfigError as err:
        raise ControllerParameterError(str(err)) from None
    if trigger == 'estimate' and config.mode != 'lqr':
        raise ControllerParameterError(
            f"trigger 'estimate' needs mode 'lqr' (the PD reads the fields), got {config.mode!r}"
        )
    return ControllerNodeConfig(
        params, config, delay, start_enabled, period, trigger, excitation, intra, streams
    )


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
            self.controller = make_controller(model, cfg.controller)
        except (ValueError, OSError) as err:
            raise ControllerParameterError(f'params {cfg.params!r}: {err}') from None
        self.controller.set_enabled(cfg.start_enabled)
        self.lqr = cfg.controller.mode == 'lqr'
        self.n_sensors = model.n_outputs // 3
        self.commands = 0  # commands published
        self.skipped_estimates = 0  # stream_thread: older estimates of a wake-up, not answered
        # the estimate input (stream thread, in-process) and the executor's callbacks
        # (stale check, enable, reference) change the core and publish: one at a time
        self._lock = threading.RLock()
        self.last_command = np.zeros(model.n_inputs)
        # the parts of each sample (LQR: currents, estimate; PD: each field, currents),
        # released in stamp order whatever order the callbacks run in
        self._currents_part = 0 if self.lqr else self.n_sensors
        self._samples = SampleAssembler(
            2 if self.lqr else self.n_sensors + 1, round(cfg.controller.input_timeout * 1e9)
        )
        self._last_level = 'OK'
        self._status_key: tuple | None = None  # what the core's level depends on
        self._last_sample_ns: int | None = None  # node clock at the last sample message
        self._pending = np.zeros(model.n_inputs)  # delay_commands: computed, not yet sent
        self._command_prefix = float_array_prefix(model.n_inputs)  # + the currents' bytes
        self._pack = struct.Struct(f'<{model.n_inputs}d').pack
        self._pub = self.create_publisher(Float64MultiArray, COMMAND_TOPIC, LOCKSTEP_COMMAND_QOS)
        try:
            self.excitation = ExcitationSchedule(cfg.excitation, cfg.controller.sample_rate)
        except LoopExcitationError as err:
            raise ControllerParameterError(f'excitation_{err}') from None
        self._first_stamp: int | None = None  # the excitation's sample 0
        self._pending_excitation = np.zeros(model.n_inputs)
        self.last_excitation = np.zeros(model.n_inputs)
        self._excitation_pub = None
        if self.excitation.enabled:
            self._excitation_pub = self.create_publisher(
                Float64MultiArray, EXCITATION_TOPIC, LOCKSTEP_COMMAND_QOS
            )
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        # the commands' bytes for composed recorders and identifiers (intra_process taps)
        self._command_tap = intra_process.tap(self.context, self.resolve_topic_name(COMMAND_TOPIC))
        self._excitation_tap = intra_process.tap(
            self.context, self.resolve_topic_name(EXCITATION_TOPIC)
        )
        self._own_taps = [self._command_tap]
        if self._excitation_pub is not None:
            self._own_taps.append(self._excitation_tap)
        for tap in self._own_taps:
            tap.add_publisher(Float64MultiArray)
        self.estimates = None  # intra_process: the estimator's channel
        self._command_input = None  # intra_process: the simulator's command input
        self.per_estimate = cfg.trigger == 'estimate'
        if self.per_estimate:  # no pairing: the estimate alone (its currents: the last command)
            self._last_estimate_ns: int | None = None
            self._estimates_seen = False
            self._estimate_reader = RawFieldReader('nav_msgs/msg/Odometry', ODOMETRY_VALUES)
            if cfg.intra_process:
                self._connect_in_process()
            self._estimate_streams = None
            self._heard_since: float | None = None  # monotonic s: estimator matched since
            if self.estimates is None:
                self._estimate_streams = open_streams(
                    self,
                    [Stream(Odometry, ESTIMATE_TOPIC, self._on_estimate_only)],
                    SENSOR_QOS,
                    own_thread=cfg.stream_thread,
                    burst=self._on_estimates,
                )
            self.create_timer(cfg.controller.input_timeout, self._check_stale)
        else:
            self.create_subscription(JointState, CURRENTS_TOPIC, self._on_currents, SENSOR_QOS)
            if self.lqr:
                self.create_subscription(Odometry, ESTIMATE_TOPIC, self._on_estimate, SENSOR_QOS)
            else:
                for k in range(self.n_sensors):
                    self.create_subscription(
                        MagneticField,
                        field_topic(k),
                        lambda m, k=k: self._on_field(k, m),
                        SENSOR_QOS,
                    )
        self.create_subscription(PoseStamped, REFERENCE_TOPIC, self._on_reference, 10)
        self.create_service(SetBool, CONTROLLER_ENABLE_SERVICE, self._on_enable)
        self.create_timer(cfg.diagnostics_period, self.publish_diagnostics)
        c = cfg.controller
        self.get_logger().info(
            f'{c.mode} on {cfg.params}, {c.sample_rate:g} Hz, limit {c.current_limit:g} A, '
            f'input timeout {1e3 * c.input_timeout:g} ms, '
            f'{"enabled" if cfg.start_enabled else "disabled"}, '
            f'{cfg.excitation.describe()}'
        )

    # ------------------------------------------------------------------ inputs
    def _publish(self, command: np.ndarray, excitation=None) -> None:
        if self.config.delay_commands:
            command, self._pending = self._pending, command
            excitation, self._pending_excitation = self._pending_excitation, excitation
        if self._excitation_pub is not None:  # the excitation part, just before its command
            if excitation is None:  # a zero command of the safety or ready checks
                excitation = np.zeros(self.controller.n_inputs)
            self.last_excitation = excitation
            data = self._command_prefix + self._pack(*excitation)
            self._excitation_pub.publish(data)
            if self._excitation_tap.listeners:
                self._excitation_tap.deliver([data])
        self.last_command = command
        values = [float(v) for v in command]
        # serialised here (template + 4 doubles): rclpy's message object cost ~3x the bytes
        data = self._command_prefix + self._pack(*values)
        if self._command_input is None or self._pub.get_subscription_count():
            self._pub.publish(data)  # composed: only for subscribers (the simulator has it)
        if self._command_tap.listeners:  # a composed recorder or identifier
            self._command_tap.deliver([data])
        if self._command_input is not None:  # intra_process: the simulator, directly
            self._command_input(values)
        self.commands += 1
        c = self.controller  # status() only when what its level depends on changed
        key = (
            getattr(c, 'lost', None),
            getattr(c, 'magnet_present', None),
            c.watchdog.safe,
            c.enabled,
            c.active,
        )
        if key == self._status_key:
            return
        self._status_key = key
        status = c.status()
        if status.level != self._last_level:
            self._last_level = status.level
            if status.level == 'ERROR':
                self.get_logger().warning(status.message)
            self.publish_diagnostics()  # an ERROR (stale input) is reported at once

    def _valid_currents(self, msg: JointState):
        currents = np.array(msg.effort, dtype=float)
        if currents.shape != (self.controller.n_inputs,) or not np.all(np.isfinite(currents)):
            self.get_logger().error(
                f'{CURRENTS_TOPIC}: expected {self.controller.n_inputs} finite currents, '
                f'got {list(msg.effort)}',
                throttle_duration_sec=1.0,
            )
            return None
        return currents

    def _on_currents(self, msg: JointState) -> None:
        self._last_sample_ns = self.get_clock().now().nanoseconds
        currents = self._valid_currents(msg)
        if currents is not None:
            self._answer(self._samples.add(self._currents_part, stamp_ns(msg), currents))

    def _on_estimate(self, msg: Odometry) -> None:
        self._answer(self._samples.add(1, stamp_ns(msg), odometry_state(msg)))

    def _on_estimate_only(self, raw: bytes) -> None:
        """``trigger: estimate``: one command per estimate, with its own stamp."""
        self._last_sample_ns = self._last_estimate_ns = self.get_clock().now().nanoseconds
        self._estimates_seen = True
        read = self._estimate_reader.read(raw)
        if read is None:
            self.get_logger().error(
                f'{ESTIMATE_TOPIC}: message not read: expected a nav_msgs/Odometry '
                '(little-endian CDR)',
                throttle_duration_sec=1.0,
            )
            return
        stamp, values = read
        self._send(stamp, self.controller.command(stamp * 1e-9, odometry_state_values(values)))

    def _on_estimates(self, taken: list[list[bytes]]) -> None:
        """``stream_thread``: answer the newest estimate of a wake-up (the others are obsolete)."""
        raws = taken[0]
        if raws:
            self.skipped_estimates += len(raws) - 1
            with self._lock:
                self._on_estimate_only(raws[-1])

    def _estimator_matched(self) -> bool:
        """Return True while an estimator's publisher is matched to the estimate input."""
        if self._estimate_streams is not None:
            return self._estimate_streams.publisher_count(0) > 0
        if self.estimates is not None:
            return True  # in-process: the estimator's channel
        topic = self.resolve_topic_name(ESTIMATE_TOPIC)
        return any(
            sub.topic_name == topic and sub.get_publisher_count() > 0 for sub in self.subscriptions
        )

    def _connect_in_process(self) -> None:
        """intra_process: the estimator's estimates and the simulator's command input."""
        estimates = intra_process.find(self.context, self.resolve_topic_name(ESTIMATE_TOPIC))
        sink = intra_process.find(self.context, self.resolve_topic_name(COMMAND_TOPIC))
        if not isinstance(estimates, intra_process.Channel):
            self.get_logger().warning(
                'intra_process: no estimator in this process (create it first): subscribing'
            )
            return
        if isinstance(sink, intra_process.CommandSink):
            self._command_input = sink.attach(self.get_name())
            if self._command_input is not None and sink.lock is not None:
                self._lock = sink.lock  # its commands take the simulator's lock: share it
        estimates.connect(self._on_estimate_values, self.get_name())
        self.estimates = estimates

    def destroy_node(self) -> None:
        """Disconnect from an estimator of this process, then destroy the node."""
        for tap in getattr(self, '_own_taps', ()):
            tap.remove_publisher()
        self._own_taps = []
        if self.estimates is not None:
            self.estimates.disconnect(self._on_estimate_values)
            self.estimates = None
        if getattr(self, '_estimate_streams', None) is not None:
            self._estimate_streams.close()
            self._estimate_streams = None
        super().destroy_node()

    def _on_estimate_values(self, stamp: int, x: np.ndarray) -> None:
        """intra_process: one command per estimate, in the estimator's thread."""
        clock = self.get_clock()  # its time without a Time object (1 us, not 3) unless sim time
        now = clock.now().nanoseconds if clock.ros_time_is_active else time.time_ns()
        self._last_sample_ns = self._last_estimate_ns = now
        self._estimates_seen = True
        with self._lock:
            self._send(stamp, self.controller.command(stamp * 1e-9, x))

    def _check_stale(self) -> None:
        """``trigger: estimate``: the stale check, under the node's lock (:meth:`_stale`)."""
        with self._lock:
            self._stale()

    def _stale(self) -> None:
        """``trigger: estimate``: no estimate for ``input_timeout`` of the node's clock.

        The core's watchdog sees only the stamps of the estimates that come;
        when they stop, this timer commands zero currents (once) and reports
        the ERROR. The first estimate after it re-arms the core's way
        (``rearm_samples`` in a row). Before the first estimate, once an
        estimator's publisher has been matched for ``READY_AFTER_S``, it
        commands zero currents every period: the controller is up, spinning
        and hears the estimates (a simulator with ``wait_for_controller``
        starts on it).
        """
        last = self._last_estimate_ns
        if not self.context.ok():
            return
        if last is None:
            # ready (zero currents until the first estimate) once an estimator is heard:
            # a simulator waiting for the controller must not step while the estimates
            # cannot reach it yet (the magnet's x and y modes grow e-fold in 20-35 ms).
            # Discovery matches each side on its own: the estimator's publisher may
            # match this subscription only tens of ms after this side did, and
            # estimates published before are lost; so hear it for READY_AFTER_S first
            now_s = time.monotonic()
            if not self._estimator_matched():
                self._heard_since = None
            elif self._heard_since is None:
                self._heard_since = now_s
            ready = self._heard_since is not None and now_s - self._heard_since >= READY_AFTER_S
            if not self._estimates_seen and ready:
                self._publish(np.zeros(self.controller.n_inputs))
            return
        now = self.get_clock().now().nanoseconds
        if now - last > self.config.controller.input_timeout * 1e9:
            self._last_estimate_ns = None  # one zero command per silence
            last_t = self.controller.watchdog.last_input or 0.0
            # the core's answer to a missing input, input_timeout after the last one
            self._publish(
                self.controller.command(last_t + 2 * self.config.controller.input_timeout)
            )

    def _on_field(self, k: int, msg: MagneticField) -> None:
        f = msg.magnetic_field
        self._answer(self._samples.add(k, stamp_ns(msg), (f.x, f.y, f.z)))

    def _answer(self, samples) -> None:
        """Publish one command per released sample, in stamp order."""
        for sample in samples:
            t = sample.stamp * 1e-9
            parts = sample.parts
            if self.lqr:
                currents, x = parts
                if x is None:  # no estimate for this sample: the core's missing-input answer
                    command = self.controller.command(t)
                else:
                    command = self.controller.command(t, x, currents)
            else:
                fields_, currents = parts[:-1], parts[-1]
                y = None
                if any(f is not None for f in fields_):
                    y = np.full(3 * self.n_sensors, np.nan)
                    for k, f in enumerate(fields_):
                        if f is not None:
                            y[3 * k : 3 * k + 3] = f
                command = self.controller.command(t, y, currents)
            self._send(sample.stamp, command)

    def _send(self, stamp: int, command: np.ndarray) -> None:
        """Publish the command for the sample stamped ``stamp`` (ns), excitation added."""
        if self._excitation_pub is None:
            self._publish(command)
        else:
            excitation = self._excitation_of(stamp)
            self._publish(command + excitation, excitation)

    def _excitation_of(self, stamp: int) -> np.ndarray:
        """Return the excitation of the sample stamped ``stamp`` (ns); zero when commanding 0."""
        if self._first_stamp is None:
            self._first_stamp = stamp
        if not self.controller.active:
            return np.zeros(self.controller.n_inputs)
        index = round((stamp - self._first_stamp) * self.config.controller.sample_rate * 1e-9)
        return self.excitation.value(index)

    def _on_reference(self, msg: PoseStamped) -> None:
        with self._lock:
            self._set_reference(msg)

    def _set_reference(self, msg: PoseStamped) -> None:
        if not self.lqr:
            self.get_logger().error(f'{REFERENCE_TOPIC} ignored: the PD holds the equilibrium')
            return
        frame = msg.header.frame_id
        if frame not in ('', BASE_FRAME):
            self.get_logger().error(
                f'{REFERENCE_TOPIC} refused: frame {frame!r}, expected {BASE_FRAME!r}'
            )
            return
        p = msg.pose.position
        try:
            self.controller.set_reference([p.x, p.y, p.z])
        except ValueError as err:
            self.get_logger().error(f'{REFERENCE_TOPIC} refused: {err}')
            return
        self.get_logger().info(f'reference {p.x:.6g} {p.y:.6g} {p.z:.6g} m')

    def _on_enable(self, request, response):
        """Switch the controller; the response names the first command it governs.

        Contract: commands are numbered from 0 in publishing order (the
        diagnostics' ``commands`` count). A response ``... from command N on``
        means that command N and every later one follow the new state: all
        zero after a disable, including a command computed before it and held
        back by ``delay_commands`` (dropped). Commands before N may still be
        in flight, and a lockstep simulator may still apply commands it
        queued before N.
        """
        enable = bool(request.data)
        with self._lock:
            self.controller.set_enabled(enable)
            if not enable:
                self._pending = np.zeros(self.controller.n_inputs)  # computed while enabled
                self._pending_excitation = np.zeros(self.controller.n_inputs)
        response.success = True
        state = 'enabled' if enable else 'disabled: zero currents'
        response.message = f'{state} from command {self.commands} on'
        self.get_logger().info(f'controller {response.message}')
        self.publish_diagnostics()
        return response

    # ------------------------------------------------------------------ diagnostics
    def publish_diagnostics(self) -> None:
        """Publish the controller's level, message, timeouts and saturations."""
        if not self.context.ok():
            return
        s = self.controller.status()
        level, message = _LEVELS.get(s.level, DiagnosticStatus.ERROR), s.message
        now_ns = self.get_clock().now().nanoseconds
        timeout_ns = self.config.controller.input_timeout * 1e9
        # the graph stopped (no sample at all): no command is sent, whatever the core says
        if self._last_sample_ns is not None and now_ns - self._last_sample_ns > max(
            timeout_ns, 2e9 * self.config.diagnostics_period
        ):
            level = DiagnosticStatus.ERROR
            message = (
                f'no sample for {(now_ns - self._last_sample_ns) * 1e-9:.2f} s: no commands '
                "sent (the driver's command_timeout zeroes the coils)"
            )
        values = {
            'mode': self.config.controller.mode,
            'enabled': str(self.controller.enabled).lower(),
            'active': str(s.active).lower(),
            'commands': self.commands,
            'last command (A)': ' '.join(f'{v:.6g}' for v in self.last_command),
            'timeouts': s.timeouts,
            'saturated commands': s.saturated,
        }
        if self.per_estimate:
            values['estimates skipped (older in a wake-up)'] = self.skipped_estimates
        if self._excitation_pub is not None:
            values['excitation'] = self.config.excitation.describe()
            values['last excitation (A)'] = ' '.join(f'{v:.6g}' for v in self.last_excitation)
        if self.lqr:
            values['reference (m)'] = ' '.join(f'{v:.6g}' for v in self.controller.reference)
        self._diag_pub.publish(
            diagnostic_array(now_ns, f'{NODE_NAME}: levitation', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Run the controller until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return run_nodes([ControllerNode], args, NODE_NAME, (ControllerParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
