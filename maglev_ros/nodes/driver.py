"""Board driver node: ``ros2 run maglev_ros driver``.

Talks to a Maggy board (or ``maglev-virtual-board``) over a serial port and
publishes on the shared topics (``docs/topics.md``), exactly like the
simulator node:

* ``maglev/sensor_<k>/field`` (sensor_msgs/MagneticField): the field of
  sensor k in tesla, frame from ``sensor_frames``, stamped with the board's
  sample time mapped to ROS time (``hardware.board_clock``: offset and drift
  against the host's system clock estimated, stamps strictly increasing; the
  system clock is the ROS time of nodes without ``use_sim_time``; after a
  (re)connection, samples are published once the link has caught up with any
  backlog, all of them, stamped with the caught-up clock). V2x fields are the raw sensor
  fields (what the model predicts); V4x fields are after the board's own
  baseline and feedthrough removal (reported in ``/diagnostics``).
* ``maglev/currents`` (sensor_msgs/JointState, names x+ x- y+ y-): effort
  = coil current in A; V2x: the current implied by the applied PWM through
  the scaling below; V4x: the measured current.
* subscribes ``maglev/currents/command`` (sensor_msgs/JointState, effort: 4
  currents in A) and sends each valid command as one packet (V2x only; V4x
  is read-only and ignores commands);
* service ``maglev/enable`` (std_srvs/SetBool): disabled means zero
  currents whatever is commanded; ``start_enabled`` sets the state at
  start-up;
* ``/diagnostics``: link state, records/s, resyncs, dropped bytes, command
  rate, rejected and clamped commands, timeouts, reconnects.

Commands pass the ROS-free :class:`~maglev_ros.hardware.command_guard.CommandGuard`
and the board's bytes the ROS-free :class:`~maglev_ros.hardware.board_stream.BoardStream`
(decode, units, board clock, catch-up); the node wires them. A command of the
wrong length or with a NaN or infinite value is rejected (nothing is sent, the
command timeout keeps running); values beyond +-``current_limit`` are clamped to
it. Both cases log a throttled warning and are counted. Zero currents are sent
when no valid command came for ``command_timeout`` s, when disabled, on shutdown
(SIGINT, SIGTERM, SIGHUP, ``destroy_node``) and after an error the I/O loop cannot
handle. The link survives unplugging: the port is reopened with exponential
back-off.

Scaling (V2x): ``counts = round(counts_per_ampere * I)``, clamped to +-4096,
with ``counts_per_ampere = 4096 * coil_resistance / supply_voltage`` unless
``counts_per_ampere`` is set (> 0).

Latency (V2x): with ``confirm_records`` (default) the newest record of each
read waits for the next record to confirm its boundary, so a record whose
tail was lost is dropped instead of published with foreign bytes; the last
record of each burst is then published with the next burst (up to 1 ms
later). A loop closed on the PC that prefers latency can set it false (USB
itself does not cut records; the decoder still resynchronises after any
damage). ``read_interval`` > 0 reads the port at most that often (several
1 ms bursts decoded and published per read): less CPU per record, up to that
much more latency (``docs/benchmarks.md``, driver section).

Composed (``intra_process: true``, :mod:`~maglev_ros.nodes.intra_process`):
the driver hands each read's samples to an estimator of its process (created
after it) in its I/O thread, takes the commands of a controller of its process
directly (the command subscription is then dropped: one command source), and
feeds the taps of composed recorders and identifiers; topics nobody
subscribes to are then not published. The loop closes in the I/O thread:
read, estimate, command, send, with no middleware hop (``maglev-lab --board``).

V4x PC control (``firmware: v4x_pc``, ROS-free loop in
:mod:`~maglev_ros.hardware.v4x_pc_poller`): the driver pings the board at
start (no answer, or a port that cannot be opened: one line naming the port
and the firmware, exit status 2), then polls it ``poll_rate`` times a second
(default 1000 Hz): each step sends 01 (sensors), 02 (currents) and 03 (the
newest command's pair differences) together and reads the three replies. The
field published is the board's processed one (``/diagnostics``: field kind),
the currents the board's measured ones; each sample is stamped with the host's
system clock when the sensor reply arrived. The firmware has no watchdog: the
coils are reset (04) on a command timeout, when disabled, on shutdown, after a
link error and at every (re)connection (docs/boards.md).

QoS: sensor fields and currents are RELIABLE, KEEP_LAST 1000 (every sample
must arrive for identification; 1000 samples = 0.2 s at 5 kHz); the command
subscription is BEST_EFFORT, KEEP_LAST 10, which matches both reliable and
best-effort publishers.
"""

from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState, MagneticField
from std_srvs.srv import SetBool

from maglev_ros.cdr import currents_layout, field_layout
from maglev_ros.cdr.batch import RawMessageBatch, SampleSerialiser
from maglev_ros.hardware.board_link import BoardLink
from maglev_ros.hardware.board_stream import BoardStream
from maglev_ros.hardware.command_guard import CommandGuard
from maglev_ros.hardware.driver_config import (
    DEFAULT_BAUD,
    MAX_READ_INTERVAL_S,
    DriverConfig,
    DriverConfigError,
    driver_config,
)
from maglev_ros.hardware.driver_health import FIELD_KINDS, DriverHealth, driver_counters
from maglev_ros.hardware.packet import WATCHDOG_S
from maglev_ros.hardware.scaling import BOARD_COIL_RESISTANCE, BOARD_SUPPLY_VOLTAGE
from maglev_ros.hardware.serial_link import Backoff, LinkError, SerialLink
from maglev_ros.hardware.v2x_stream import DecoderStats
from maglev_ros.hardware.v4x_pc_link import V4xPcLink
from maglev_ros.hardware.v4x_pc_poller import DEFAULT_POLL_RATE, REPLY_TIMEOUT_S, V4xPcPoller
from maglev_ros.nodes import intra_process
from maglev_ros.nodes.contract import (  # shared with the simulator
    COMMAND_QOS,
    DIAGNOSTICS_QOS,
    SENSOR_QOS,
    diagnostic_array,
    run_nodes,
)
from maglev_ros.nodes.messages import CommandMessageError, command_currents
from maglev_ros.nodes.params import NodeParameterError, Param, ParameterTable, integer
from maglev_ros.topics import (
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    DIAGNOSTICS_TOPIC,
    ENABLE_SERVICE,
    field_topic,
    sensor_frame,
)

__all__ = [
    'PARAMETERS',
    'DriverConfig',
    'DriverNode',
    'DriverParameterError',
    'BoardNotFoundError',
    'build_config',
    'main',
]

NODE_NAME = 'maglev_driver'
WARN_THROTTLE_S = 1.0  # s between repeated warnings of one kind
MAX_POLL_RATE = 5000.0  # Hz: the V4x PC-control board samples every 200 us
GIL_SWITCH_S = 0.0002  # s, the interpreter's switch interval while a V4x PC board is polled


class DriverParameterError(NodeParameterError):
    """A driver parameter has an invalid value."""


class BoardNotFoundError(DriverParameterError):
    """The port holds no board answering as the firmware parameter says (V4x PC control)."""


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise DriverParameterError(f'{name} must be a positive finite number, got {value!r}')
    return value


def _positive_or_zero(name: str, value: float) -> float:
    return value if value == 0 else _positive(name, value)


def _firmware(name: str, value: str) -> str:
    if value not in DEFAULT_BAUD:
        raise DriverParameterError(
            f"{name} must be 'v2x', 'v4x' or 'v4x_pc' (V4x PC control), got {value!r}"
        )
    return value


def _port(name: str, value: str) -> str:
    if not value:
        raise DriverParameterError(f'{name} must be a device path, got an empty string')
    return value


def _baudrate(name: str, value: int) -> int:
    if value < 0:
        raise DriverParameterError(f'{name} must be > 0 (0: default), got {value}')
    return value


def _command_timeout(name: str, value: float) -> float:
    _positive(name, value)
    if value > WATCHDOG_S:
        raise DriverParameterError(
            f"{name} must be at most the firmware's {WATCHDOG_S:g} s watchdog (the board "
            f'zeroes its PWM after that long without a packet), got {value!r}'
        )
    return value


def _read_interval(name: str, value: float) -> float:
    if not 0.0 <= value <= MAX_READ_INTERVAL_S:
        raise DriverParameterError(
            f'{name} must be in 0 .. {MAX_READ_INTERVAL_S} s, got {value!r}'
        )
    return value


def _poll_rate(name: str, value: float) -> float:
    if not (value == 0 or 100.0 <= value <= MAX_POLL_RATE):
        raise DriverParameterError(
            f'{name} must be 0 (as fast as the board answers) or in 100 .. '
            f'{MAX_POLL_RATE:g} Hz (the board samples at 5 kHz), got {value!r}'
        )
    return value


def _frames(name: str, value: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(f for f in value if f)  # empty strings: the default frame


PARAMETERS = ParameterTable(
    NODE_NAME,
    DriverParameterError,
    {
        'port': Param('/dev/ttyACM0', 'serial device path (a udev symlink is best)', check=_port),
        'firmware': Param(
            'v2x',
            "board firmware: 'v2x' (binary stream), 'v4x' (text, read only) or 'v4x_pc' "
            '(V4x PC control, COBS request/response)',
            check=_firmware,
        ),
        'baudrate': Param(0, 'baud rate; 0: 9600 for v2x, 115200 for v4x', check=_baudrate),
        'n_sensors': Param(
            1, 'number of sensors per record (not announced by the board)', check=integer(1, 64)
        ),
        'sensor_frames': Param(
            [],
            f'frame id per sensor; empty: {sensor_frame("<k>")}',
            kind='string_array',
            check=_frames,
        ),
        'supply_voltage': Param(
            BOARD_SUPPLY_VOLTAGE, 'H-bridge supply voltage in V (V2x scaling)', check=_positive
        ),
        'coil_resistance': Param(
            BOARD_COIL_RESISTANCE,
            'coil resistance in ohm, wiring included (V2x scaling)',
            check=_positive,
        ),
        'counts_per_ampere': Param(
            0.0, 'PWM counts per A; > 0 overrides voltage/resistance', check=_positive_or_zero
        ),
        'current_limit': Param(
            0.0,
            'largest commanded |current| in A; 0: full duty (V/R)',
            check=_positive_or_zero,
            mutable=True,
        ),
        'command_timeout': Param(
            0.1,
            f"s without a valid command before zero currents (at most the firmware's "
            f'{WATCHDOG_S:g} s watchdog)',
            check=_command_timeout,
            mutable=True,
        ),
        'start_enabled': Param(False, 'enable state at start-up (disabled: zero currents)'),
        'reconnect_min_delay': Param(
            0.2, 's, first delay before reopening the port', check=_positive
        ),
        'reconnect_max_delay': Param(
            5.0, 's, longest delay between reopen attempts', check=_positive
        ),
        'diagnostics_period': Param(
            1.0, f's between {DIAGNOSTICS_TOPIC} messages', check=_positive
        ),
        'confirm_records': Param(
            True,
            'V2x: hold the newest record until the next confirms it (a cut record is then '
            'dropped, not published corrupted; up to 1 ms more latency for the last record '
            'of each burst); false: publish at once',
        ),
        'read_interval': Param(
            0.0,
            's, shortest time between reads of the port (0: every burst as it arrives; '
            '0.002: two 1 ms bursts per read, less CPU, up to 2 ms more latency)',
            check=_read_interval,
        ),
        'poll_rate': Param(
            DEFAULT_POLL_RATE,
            'v4x_pc: Hz, steps (read field and currents, write the command) per second; '
            '0: as fast as the board answers',
            check=_poll_rate,
        ),
        'intra_process': Param(
            False,
            "hand the samples to an estimator of this process and take its controller's "
            'commands directly, not through the middleware (composed loops)',
        ),
    },
)
_PARAMETERS = PARAMETERS  # the name test_launch and older callers use


def build_config(values: dict) -> DriverConfig:
    """Validate raw parameter values and build a ``DriverConfig``.

    The same rules apply at start-up and to run-time changes of the mutable
    parameters (``current_limit``, ``command_timeout``).

    Parameters
    ----------
    values : dict
        Parameter name to value, as declared by ``DriverNode`` (a missing
        name takes its default).

    Returns
    -------
    DriverConfig
        The validated configuration.

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
    """The board driver (see the module docstring): ROS wiring around the hardware cores.

    The :class:`~maglev_ros.hardware.command_guard.CommandGuard` decides what
    reaches the coils; the :class:`~maglev_ros.hardware.board_stream.BoardStream`
    turns the board's bytes into stamped samples. This node wires them to the
    serial link (an I/O thread), the topics, the enable service and
    ``/diagnostics``.

    Parameters
    ----------
    open_port : bool, optional
        Open the port and start the I/O thread now (default); False: at
        :meth:`start` (a composed loop starts its board once every node is up).
    **kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``,
        ``parameter_overrides``).

    Raises
    ------
    DriverParameterError
        If a parameter is invalid.
    """

    def __init__(self, *, open_port: bool = True, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._lock = threading.Lock()  # the command guard and the link's writes
        self.guard: CommandGuard | None = None
        self.config = cfg = build_config(PARAMETERS.declare(self))
        self.add_on_set_parameters_callback(PARAMETERS.on_set(self, build_config))
        self._v2x = cfg.firmware == 'v2x'
        self._pc = cfg.firmware == 'v4x_pc'  # V4x PC control: polled, commands as pairs
        self.guard = CommandGuard(
            cfg.scaling,
            cfg.current_limit,
            cfg.command_timeout,
            enabled=cfg.start_enabled,
            read_only=cfg.firmware == 'v4x',
            pairs=self._pc,
        )
        backoff = Backoff(cfg.reconnect_min_delay, cfg.reconnect_max_delay)
        self._switch_interval = None  # the interpreter's, while a V4x PC-control loop runs
        if self._pc:
            # each step waits for the board's reply: a thread holding the GIL would hand
            # it back only after the switch interval (default 5 ms), capping the poll rate
            self._switch_interval = sys.getswitchinterval()
            sys.setswitchinterval(min(self._switch_interval, GIL_SWITCH_S))
            self.stream = None
            self.link = V4xPcPoller(
                V4xPcLink(cfg.port, timeout=REPLY_TIMEOUT_S),
                backoff,
                self.get_logger(),
                poll_rate=cfg.poll_rate,
            )
        else:
            self.stream = BoardStream(
                cfg.firmware,
                cfg.n_sensors,
                cfg.scaling,
                confirm_records=cfg.confirm_records,
                read_interval=cfg.read_interval,
            )
            self.link = BoardLink(
                SerialLink(cfg.port, cfg.baudrate),
                self.stream,
                backoff,
                self.get_logger(),
                writes=self._v2x,
            )
        self.health = DriverHealth(cfg.firmware, time.monotonic())
        self._field_pubs = [
            self.create_publisher(MagneticField, field_topic(k), SENSOR_QOS)
            for k in range(cfg.n_sensors)
        ]
        self._current_pub = self.create_publisher(JointState, CURRENTS_TOPIC, SENSOR_QOS)
        self._serialiser = SampleSerialiser(
            [RawMessageBatch(field_layout(frame)) for frame in cfg.sensor_frames]
            + [RawMessageBatch(currents_layout())]
        )
        # per sample: the field of each sensor, then the currents (SampleSerialiser order)
        self._handles = [pub.handle for pub in self._field_pubs] + [self._current_pub.handle]
        self._publish_calls: dict[int, list] = {}  # per burst length: bound publish_raw calls
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        self._command_sub = self.create_subscription(
            JointState, COMMAND_TOPIC, self._on_command, COMMAND_QOS
        )
        self.samples_source: intra_process.Channel | None = None
        self._intra: list = []
        self._taps: list = []
        if cfg.intra_process:
            self._wire_in_process()
        self.create_service(SetBool, ENABLE_SERVICE, self._on_enable)
        self.create_timer(min(0.02, cfg.command_timeout / 4), self._check_timeout)
        self.create_timer(cfg.diagnostics_period, self._publish_diagnostics)
        # compiled kernels load (0.5 to 1.5 s holding the GIL) now, not in the I/O thread
        if self.stream is not None:
            self.stream.warm_up()
        self._serialiser.serialise(np.zeros(1, np.int64), np.zeros((1, 3 * cfg.n_sensors + 4)))
        self._stop = threading.Event()
        self._closed = False
        self._io = threading.Thread(target=self._io_loop, name='maglev-driver-io', daemon=True)
        if open_port:
            self.start()
        # after start: a V4x PC-control board that is not there gives one line only
        polled = f', polled at {cfg.poll_rate:g} Hz' if self._pc and cfg.poll_rate else ''
        self.get_logger().info(
            f'{cfg.firmware} board on {cfg.port}, {cfg.n_sensors} sensor(s), publishing fields: '
            f'{FIELD_KINDS[cfg.firmware]}{polled}; '
            f'{cfg.scaling.counts_per_ampere:.1f} counts/A, limit {cfg.current_limit:.3f} A, '
            f'{"enabled" if self.enabled else "disabled"}'
        )

    def start(self) -> None:
        """Open the port and start the I/O thread (if ``open_port`` was False; idempotent).

        Raises
        ------
        BoardNotFoundError
            V4x PC control: the port cannot be opened or nothing answers the
            ping (the message names the port and the firmware expected).
        """
        if self._io.ident is None and not self._closed:
            if self._pc:  # a board that is not there is a wrong parameter: say so, exit
                try:
                    self.link.open()
                except LinkError as err:
                    raise BoardNotFoundError(f'{err} (parameters port, firmware)') from None
            self._io.start()

    # -- state ------------------------------------------------------------------

    @property
    def config(self) -> DriverConfig:
        """The validated parameters (run-time changes reach the command guard)."""
        return self._config

    @config.setter
    def config(self, config: DriverConfig) -> None:
        """Store a new configuration and pass its limit and timeout to the guard.

        Parameters
        ----------
        config : DriverConfig
            The validated parameters.
        """
        self._config = config
        if self.guard is not None:
            with self._lock:
                self.guard.configure(config.current_limit, config.command_timeout)

    @property
    def counters(self) -> dict[str, int]:
        """Records, commands sent/rejected/clamped/unsent/ignored, timeouts, link events."""
        return driver_counters(self.link, self.guard)

    @property
    def link_state(self) -> str:
        """``connecting``, ``waiting for board``, ``connected`` or ``disconnected``."""
        return self.link.state

    @property
    def last_info(self) -> str:
        """Text of the board's last info line (V4x)."""
        return self.link.last_info

    @property
    def decoder_stats(self) -> DecoderStats:
        """Counters of the record decoder of the current connection (V2x)."""
        return self.stream.decoder_stats

    @property
    def enabled(self) -> bool:
        """Whether commands are applied (else zero currents are sent)."""
        return self.guard.enabled

    # -- commands ---------------------------------------------------------------

    def _send(self, counts: np.ndarray) -> None:
        """Send PWM counts (shape (4,)): one packet (V2x), the next step's 03 (V4x PC)."""
        self.link.send(counts)

    def _zero_locked(self) -> None:
        """Zero the coils (V2x: zero packet; V4x PC control: 04); caller holds the lock."""
        self.link.send_zero(self.guard.zero)

    def _on_command(self, msg: JointState) -> None:
        try:
            currents = command_currents(msg)
        except CommandMessageError as err:
            self.get_logger().warning(f'rejected command: {err}', throttle_duration_sec=1.0)
            return
        self._take_command(currents)

    def _take_command(self, values) -> None:
        """Pass one command (currents, A) through the guard; send what it allows."""
        with self._lock:
            decision = self.guard.command(values, time.monotonic_ns())
            if decision.counts is not None:
                self._send(decision.counts)
        if decision.warning:
            self.get_logger().warning(decision.warning, throttle_duration_sec=WARN_THROTTLE_S)

    def _on_enable(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        with self._lock:
            if self.guard.set_enabled(request.data) is not None:
                self._zero_locked()
        response.success = True
        response.message = 'enabled' if self.enabled else 'disabled: zero currents sent'
        self.get_logger().info(f'driver {response.message}')
        return response

    def _check_timeout(self) -> None:
        with self._lock:
            age = self.guard.check_timeout(time.monotonic_ns())
            if age is None:
                return
            self._zero_locked()
        self.get_logger().warning(
            f'no valid command for {age:.3f} s > {self.config.command_timeout} s: '
            'zero currents sent',
            throttle_duration_sec=WARN_THROTTLE_S,
        )

    def _send_zero(self) -> None:
        with self._lock:
            self._zero_locked()

    # -- composition (intra_process) ---------------------------------------------

    def _wire_in_process(self) -> None:
        """Register the samples channel, the command sink and the topics' taps."""
        n = self.config.n_sensors
        self.samples_source = intra_process.Channel(tuple(range(n)))
        self.samples_source.on_error = self._on_listener_error
        sink = intra_process.CommandSink(self._take_command, self._command_source_attached)
        self._intra = [
            (self.resolve_topic_name(CURRENTS_TOPIC), self.samples_source),
            (self.resolve_topic_name(COMMAND_TOPIC), sink),
        ]
        for topic, obj in self._intra:
            intra_process.register(self.context, topic, obj)
        # per sample: each field, then the currents (the serialiser's order)
        topics = [field_topic(k) for k in range(n)] + [CURRENTS_TOPIC]
        classes = [MagneticField] * n + [JointState]
        for topic, cls in zip(topics, classes, strict=True):
            found = intra_process.tap(self.context, self.resolve_topic_name(topic))
            found.add_publisher(cls)
            found.on_error = self._on_listener_error
            self._taps.append(found)
        self._sample_pubs = [*self._field_pubs, self._current_pub]

    def _on_listener_error(self, name: str, err: Exception) -> None:
        self.get_logger().error(
            f'{name}: samples not taken in this process: {err}',
            throttle_duration_sec=WARN_THROTTLE_S,
        )

    def _command_source_attached(self, name: str) -> None:
        """Drop the command subscription: a controller of this process sends them directly."""
        self.destroy_subscription(self._command_sub)
        self._command_sub = None
        self.get_logger().info(f'commands from {name} in this process (intra_process)')

    def _hand_over(self, stamps: np.ndarray, values: np.ndarray) -> None:
        """Composed: publish to subscribers, feed the taps, then the samples channel.

        The taps (recorders, identifiers) get the samples before the estimator
        does: the command that answers them then follows them, as from the
        simulator. With a tap dispatcher in the context they are queued and
        handed on after the command is sent (:func:`~.intra_process.pump_taps`).
        """
        active = [pub.get_subscription_count() > 0 for pub in self._sample_pubs]
        tapped = [t.listeners > 0 for t in self._taps]
        if any(active) or any(tapped):
            messages = self._serialiser.serialise(stamps, values)
            k = len(self._taps)
            for i, (a, t) in enumerate(zip(active, tapped, strict=True)):
                if a:
                    publish = self._handles[i].publish_raw
                    for message in messages[i::k]:
                        publish(message)
                if t:
                    self._taps[i].deliver(messages[i::k])
        if self.samples_source.listeners:
            n_fields = 3 * self.config.n_sensors
            self.samples_source.deliver(
                intra_process.SampleBlock(stamps, values[:, :n_fields], values[:, n_fields:])
            )
        intra_process.pump_taps(self.context)  # deferred taps: after the command is sent

    # -- board I/O --------------------------------------------------------------

    def _io_loop(self) -> None:
        self.link.run(
            self._stop, self._publish, self._send_zero, self.config.read_interval, self.context.ok
        )

    def _publish(self, stamps: np.ndarray, values: np.ndarray) -> None:
        """Publish n samples: stamps (n,) ns; values (n, 3 N + 4): each field (T), currents (A).

        Messages are serialised in one go (``SampleSerialiser``) and published
        as bytes; per sample, sensor fields first, then the currents.
        """
        if self.samples_source is not None:
            self._hand_over(stamps, values)
            return
        n = stamps.shape[0]
        messages = self._serialiser.serialise(stamps, values)
        # Publisher.publish(bytes) checks the type and guards the handle per
        # message; the raw handles are safe here: the node destroys its
        # publishers only after close() has joined this thread.
        publishers = self._publish_calls.get(n)
        if publishers is None:  # per sample: each field, then the currents
            publishers = [handle.publish_raw for handle in self._handles] * n
            if len(self._publish_calls) < 64:
                self._publish_calls[n] = publishers
        for publish, message in zip(publishers, messages, strict=True):
            publish(message)

    # -- diagnostics ------------------------------------------------------------

    def _publish_diagnostics(self) -> None:
        health = self.health.report(self.link, self.guard, time.monotonic())
        self._diag_pub.publish(
            diagnostic_array(
                self.get_clock().now().nanoseconds,
                f'{NODE_NAME}: board link',
                health.level,
                health.message,
                health.values,
                hardware_id=self.config.port,
            )
        )

    # -- shutdown ---------------------------------------------------------------

    def close(self) -> None:
        """Stop the I/O thread, zero the coils and close the port (idempotent).

        V2x: a zero packet; V4x PC control: the link's close sends ``04``.
        """
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._io.ident is not None:  # started
            self._io.join(timeout=2.0)
        if self._v2x and self.link.serial.is_open:
            self._send_zero()
        self.link.close()

    def destroy_node(self) -> None:
        """Close the board link (zero currents first), then destroy the node."""
        self.close()
        if self._switch_interval is not None:
            sys.setswitchinterval(self._switch_interval)
            self._switch_interval = None
        for topic, obj in self._intra:
            intra_process.unregister(self.context, topic, obj)
        self._intra = []
        for found in self._taps:
            found.remove_publisher()
        self._taps = []
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the driver until SIGINT, SIGTERM or SIGHUP.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return run_nodes([DriverNode], args, NODE_NAME, (DriverParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
