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
* subscribes ``maglev/currents/command`` (std_msgs/Float64MultiArray, 4
  currents in A) and sends each valid command as one packet (V2x only; V4x
  is read-only and ignores commands);
* service ``maglev/enable`` (std_srvs/SetBool): disabled means zero
  currents whatever is commanded; ``start_enabled`` sets the state at
  start-up;
* ``/diagnostics``: link state, records/s, resyncs, dropped bytes, command
  rate, rejected and clamped commands, timeouts, reconnects.

Commands: a command of the wrong length or with a NaN or infinite value is
rejected (nothing is sent, the command timeout keeps running); values
beyond +-``current_limit`` are clamped to it. Both cases log a throttled
warning and are counted. Zero currents are sent when no valid command came
for ``command_timeout`` s, when disabled, on shutdown (SIGINT, SIGTERM,
``destroy_node``) and after an error the I/O loop cannot handle. The link
survives unplugging: the port is reopened with exponential back-off.

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

QoS: sensor fields and currents are RELIABLE, KEEP_LAST 1000 (every sample
must arrive for identification; 1000 samples = 0.2 s at 5 kHz); the command
subscription is BEST_EFFORT, KEEP_LAST 10, which matches both reliable and
best-effort publishers.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool

from maglev_ros.hardware.board_clock import BoardClock
from maglev_ros.hardware.packet import WATCHDOG_S, encode_command
from maglev_ros.hardware.scaling import BOARD_COIL_RESISTANCE, BOARD_SUPPLY_VOLTAGE, CurrentScaling
from maglev_ros.hardware.serial_link import Backoff, LinkError, SerialLink
from maglev_ros.hardware.v2x_stream import (
    BURST_RECORDS,
    SAMPLE_PERIOD_US,
    DecoderStats,
    RecordDecoder,
    pack_records,
)
from maglev_ros.hardware.v4x_telemetry import InfoMessage, Severity, TelemetryStream
from maglev_ros.nodes.cdr_batch import RawMessageBatch, SampleSerialiser
from maglev_ros.nodes.contract import (  # shared with the simulator
    COMMAND_QOS,
    DIAGNOSTICS_QOS,
    SENSOR_QOS,
    currents_layout,
    field_layout,
    run_nodes,
)
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
    'build_config',
    'main',
]

NODE_NAME = 'maglev_driver'
DEFAULT_BAUD = {'v2x': 9600, 'v4x': 115200}  # ignored by USB CDC, set anyway
WARN_THROTTLE_S = 1.0  # s between repeated warnings of one kind
MAX_READ_INTERVAL_S = 0.05  # s: 50 ms of 3-sensor V2x data is 12 KB, inside a pty's buffer
BURST_PERIOD_S = 0.001  # s between the board's bursts (V2x; V4x lines come at most as often)
MAX_HELD_RECORDS = 25_000  # 5 s at 5 kHz: a link that never looks caught up publishes anyway
_ZERO = np.zeros(4)


class DriverParameterError(NodeParameterError):
    """A driver parameter has an invalid value."""


@dataclass(frozen=True)
class DriverConfig:
    """Validated driver parameters (see the module docstring for meanings).

    Attributes
    ----------
    port : str
        Serial device path.
    firmware : str
        ``'v2x'`` or ``'v4x'``.
    baudrate : int
        Baud rate.
    n_sensors : int
        Sensors per record or line.
    sensor_frames : tuple of str
        Frame id of each sensor's field messages.
    scaling : CurrentScaling
        Current to PWM map (V2x).
    current_limit : float
        Largest commanded current magnitude in A.
    command_timeout : float
        s without a valid command before zero currents are sent.
    start_enabled : bool
        Enable state at start-up.
    reconnect_min_delay, reconnect_max_delay : float
        Back-off bounds in s for reopening the port.
    diagnostics_period : float
        s between diagnostics messages.
    confirm_records : bool
        Hold the newest V2x record of each read until the next record
        confirms its boundary (see ``hardware.v2x_stream``).
    read_interval : float
        Shortest time in s between reads of the port (0: read as soon as data
        arrives, every burst).
    """

    port: str
    firmware: str
    baudrate: int
    n_sensors: int
    sensor_frames: tuple[str, ...]
    scaling: CurrentScaling
    current_limit: float
    command_timeout: float
    start_enabled: bool
    reconnect_min_delay: float
    reconnect_max_delay: float
    diagnostics_period: float
    confirm_records: bool = True
    read_interval: float = 0.0


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise DriverParameterError(f'{name} must be a positive finite number, got {value!r}')
    return value


def _positive_or_zero(name: str, value: float) -> float:
    return value if value == 0 else _positive(name, value)


def _firmware(name: str, value: str) -> str:
    if value not in DEFAULT_BAUD:
        raise DriverParameterError(f"{name} must be 'v2x' or 'v4x', got {value!r}")
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


def _frames(name: str, value: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(f for f in value if f)  # empty strings: the default frame


PARAMETERS = ParameterTable(
    NODE_NAME,
    DriverParameterError,
    {
        'port': Param('/dev/ttyACM0', 'serial device path (a udev symlink is best)', check=_port),
        'firmware': Param(
            'v2x', "board firmware family: 'v2x' (binary) or 'v4x' (text)", check=_firmware
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
    v = PARAMETERS.validate(values)
    n_sensors = v['n_sensors']
    frames = v['sensor_frames'] or tuple(sensor_frame(k) for k in range(n_sensors))
    if len(frames) != n_sensors:
        raise DriverParameterError(
            f'sensor_frames must name {n_sensors} frames (n_sensors), got {list(frames)}'
        )
    if v['counts_per_ampere']:
        scaling = CurrentScaling(v['counts_per_ampere'])
    else:
        scaling = CurrentScaling.from_supply(v['supply_voltage'], v['coil_resistance'])
    min_delay, max_delay = v['reconnect_min_delay'], v['reconnect_max_delay']
    if max_delay < min_delay:
        raise DriverParameterError(
            f'reconnect_max_delay must be >= reconnect_min_delay ({min_delay}), got {max_delay}'
        )
    return DriverConfig(
        port=v['port'],
        firmware=v['firmware'],
        baudrate=v['baudrate'] or DEFAULT_BAUD[v['firmware']],
        n_sensors=n_sensors,
        sensor_frames=frames,
        scaling=scaling,
        current_limit=v['current_limit'] or scaling.max_current,
        command_timeout=v['command_timeout'],
        start_enabled=v['start_enabled'],
        reconnect_min_delay=min_delay,
        reconnect_max_delay=max_delay,
        diagnostics_period=v['diagnostics_period'],
        confirm_records=v['confirm_records'],
        read_interval=v['read_interval'],
    )


class DriverNode(Node):
    """The board driver (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``,
        ``parameter_overrides``).

    Raises
    ------
    DriverParameterError
        If a parameter is invalid.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.config = build_config(PARAMETERS.declare(self))
        self.add_on_set_parameters_callback(PARAMETERS.on_set(self, build_config))
        cfg = self.config
        self._v2x = cfg.firmware == 'v2x'
        self._link = SerialLink(cfg.port, cfg.baudrate)
        self._backoff = Backoff(cfg.reconnect_min_delay, cfg.reconnect_max_delay)
        self._decoder = RecordDecoder(cfg.n_sensors, confirm=cfg.confirm_records)
        self._telemetry = TelemetryStream(cfg.n_sensors)
        self._board_clock = BoardClock()
        self._catching_up = True  # after (re)connecting, until a read brings no backlog
        self._held: list[tuple[np.ndarray, np.ndarray]] = []  # samples kept meanwhile
        # records a read brings when the link keeps up: the bursts of one read interval
        # (at least one 1 ms burst) and one more for timing jitter, and the held-back record
        self._caught_up_records = (
            BURST_RECORDS * (max(1, math.ceil(cfg.read_interval / BURST_PERIOD_S - 1e-9)) + 1) + 1
        )
        self._lock = threading.Lock()  # command state
        self._enabled = cfg.start_enabled
        self._last_command_ns: int | None = None
        self._timed_out = False
        self._applied = np.zeros(4, dtype=np.int64)  # PWM counts last sent
        self.link_state = 'connecting'
        self._connections = 0
        self.counters = dict.fromkeys(
            (
                'records',
                'commands_sent',
                'commands_rejected',
                'commands_clamped',
                'commands_unsent',
                'commands_ignored',
                'timeouts',
                'reconnects',
                'io_errors',
                'info_messages',
                'resyncs',
                'dropped_bytes',
            ),
            0,
        )
        self._base = {'resyncs': 0, 'dropped_bytes': 0}  # of earlier connections
        self._rate_mark = (time.monotonic(), 0, 0)
        self.last_info = ''
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
        self.create_subscription(Float64MultiArray, COMMAND_TOPIC, self._on_command, COMMAND_QOS)
        self.create_service(SetBool, ENABLE_SERVICE, self._on_enable)
        self.create_timer(min(0.02, cfg.command_timeout / 4), self._check_timeout)
        self.create_timer(cfg.diagnostics_period, self._publish_diagnostics)
        kind = 'raw sensor fields' if self._v2x else 'fields after on-board baseline removal'
        self.get_logger().info(
            f'{cfg.firmware} board on {cfg.port}, {cfg.n_sensors} sensor(s), publishing {kind}; '
            f'{cfg.scaling.counts_per_ampere:.1f} counts/A, limit {cfg.current_limit:.3f} A, '
            f'{"enabled" if self._enabled else "disabled"}'
        )
        self._load_compiled_paths()
        self._stop = threading.Event()
        self._closed = False
        self._io = threading.Thread(target=self._io_loop, name='maglev-driver-io', daemon=True)
        self._io.start()

    def _load_compiled_paths(self) -> None:
        """Run the decoder and the serialiser once on made-up records, before any I/O.

        Their numba kernels load (or compile) on first use, 0.5 to 1.5 s
        holding the GIL; in the I/O thread that stall would overflow the
        publishers' history with the backlog of the board's records.
        """
        n = self.config.n_sensors
        decoder = RecordDecoder(n, confirm=self.config.confirm_records)
        stamps = SAMPLE_PERIOD_US * np.arange(2 * BURST_RECORDS)
        decoder.feed(
            pack_records(stamps, np.zeros((stamps.size, n, 3)), np.zeros((stamps.size, 4)))
        )
        self._serialiser.serialise(np.zeros(1, np.int64), np.zeros((1, 3 * n + 4)))

    # -- commands ---------------------------------------------------------------

    @property
    def decoder_stats(self) -> DecoderStats:
        """Counters of the record decoder of the current connection (V2x)."""
        return self._decoder.stats

    @property
    def enabled(self) -> bool:
        """Whether commands are applied (else zero currents are sent)."""
        return self._enabled

    def _send(self, currents: np.ndarray) -> None:
        """Send currents (A, shape (4,)) as one packet (V2x); count failures."""
        if not self._v2x:
            return
        counts = self.config.scaling.to_counts(currents)
        try:
            self._link.write(encode_command(counts))
        except LinkError:
            self.counters['commands_unsent'] += 1
            return
        self._applied = counts
        self.counters['commands_sent'] += 1

    def _on_command(self, msg: Float64MultiArray) -> None:
        log = self.get_logger()
        if not self._v2x:
            self.counters['commands_ignored'] += 1
            log.warning(
                'command ignored: the V4x firmware is read-only (its own controller runs)',
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            return
        values = np.asarray(msg.data, dtype=float)
        if values.shape != (4,):
            self.counters['commands_rejected'] += 1
            log.warning(
                f'rejected command: need 4 currents (x+, x-, y+, y-), got {values.size}',
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            return
        if not np.all(np.isfinite(values)):
            self.counters['commands_rejected'] += 1
            log.warning(
                f'rejected command: currents must be finite, got {values.tolist()}',
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            return
        limit = self.config.current_limit
        if np.any(np.abs(values) > limit):
            self.counters['commands_clamped'] += 1
            log.warning(
                f'clamped command {values.tolist()} A to +-{limit:.3f} A',
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            values = np.clip(values, -limit, limit)
        with self._lock:
            self._last_command_ns = time.monotonic_ns()
            self._timed_out = False
            self._send(values if self._enabled else _ZERO)

    def _on_enable(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        with self._lock:
            self._enabled = bool(request.data)
            if not self._enabled:
                self._send(_ZERO)
        response.success = True
        response.message = 'enabled' if self._enabled else 'disabled: zero currents sent'
        self.get_logger().info(f'driver {response.message}')
        return response

    def _check_timeout(self) -> None:
        with self._lock:
            if self._last_command_ns is None or self._timed_out:
                return
            age = (time.monotonic_ns() - self._last_command_ns) * 1e-9
            if age > self.config.command_timeout:
                self._timed_out = True
                self.counters['timeouts'] += 1
                self._send(_ZERO)
                self.get_logger().warning(
                    f'no valid command for {age:.3f} s > {self.config.command_timeout} s: '
                    'zero currents sent',
                    throttle_duration_sec=WARN_THROTTLE_S,
                )

    # -- board I/O --------------------------------------------------------------

    def _io_loop(self) -> None:
        log = self.get_logger()
        interval = self.config.read_interval
        while not self._stop.is_set():
            if not self._link.is_open:
                try:
                    self._link.open()
                except LinkError as err:
                    self.link_state = 'waiting for board'
                    delay = self._backoff.next_delay()
                    log.warning(f'{err}; retrying in {delay:.1f} s', throttle_duration_sec=5.0)
                    self._stop.wait(delay)
                    continue
                self._on_connected()
            try:
                data = self._link.read()
                if data:
                    read_at = time.monotonic()
                    self._handle(data)
                    if interval:  # let bursts collect: one read, decode, publish for several
                        self._stop.wait(interval - (time.monotonic() - read_at))
            except LinkError as err:
                self._on_disconnected(f'link lost: {err}')
            except Exception as err:  # noqa: BLE001 - zero the coils, then reconnect
                self.counters['io_errors'] += 1
                log.error(f'unexpected error on the board link: {err!r}; zeroing and reconnecting')
                with self._lock:
                    self._send(_ZERO)
                self._on_disconnected('error')
                self._stop.wait(self._backoff.next_delay())

    def _on_connected(self) -> None:
        self._connections += 1
        self.counters['reconnects'] = self._connections - 1
        self._backoff.reset()
        self._decoder = RecordDecoder(self.config.n_sensors, confirm=self.config.confirm_records)
        self._telemetry = TelemetryStream(self.config.n_sensors)
        self._board_clock = BoardClock()  # the board may have been power-cycled
        self._catching_up = True  # see _deliver
        self._held.clear()
        self.link_state = 'connected'
        self.get_logger().info(f'connected to {self.config.port}')
        with self._lock:
            self._send(_ZERO)  # a known state; applied once the board's loop runs

    def _on_disconnected(self, reason: str) -> None:
        self._link.close()
        self._base['resyncs'] += self._decoder.stats.resyncs
        self._base['dropped_bytes'] += self._decoder.stats.dropped_bytes
        self._decoder = RecordDecoder(self.config.n_sensors, confirm=self.config.confirm_records)
        self.link_state = 'disconnected'
        self.get_logger().warning(f'{self.config.port}: {reason}')

    def _handle(self, data: bytes) -> None:
        host_ns = time.time_ns()  # system time: the ROS time of a node without sim time
        if self._v2x:
            batch = self._decoder.feed(data)
            if len(batch):
                n = len(batch)
                values = np.empty((n, self._serialiser.n_values))  # each field (T), currents (A)
                np.multiply(
                    batch.field_mT.reshape(n, -1), 1e-3, out=values[:, :-4], dtype=np.float64
                )  # mT -> T
                self.config.scaling.to_current(batch.pwm, out=values[:, -4:])
                self._deliver(batch.time_us, values, host_ns)
            return
        samples = []
        for item in self._telemetry.feed(data):
            if isinstance(item, InfoMessage):
                self.counters['info_messages'] += 1
                self.last_info = item.text
                if item.severity >= Severity.WARN:
                    self.get_logger().warning(f'board: {item.text}')
                else:
                    self.get_logger().info(f'board: {item.text}')
            else:
                samples.append(item)
        if samples:
            board_us = np.array([round(s.time * 1e6) for s in samples], dtype=np.int64)
            field_t = np.stack([s.field_mT for s in samples]) * 1e-3
            currents = np.stack([s.current for s in samples])
            self._deliver(
                board_us, np.hstack([field_t.reshape(len(samples), -1), currents]), host_ns
            )

    def _deliver(self, board_us: np.ndarray, values: np.ndarray, host_ns: int) -> None:
        """Observe the board clock, stamp the samples and publish them.

        After a (re)connection the first reads may bring a backlog (the board
        streamed while this thread was not reading yet: a busy start-up, a
        stale OS buffer). The newest record of such a read is old, so its
        observation would put the clock's first offset late by the backlog's
        age, and correcting that later would hold stamps back. Until a read
        brings no more than the records a read normally brings (the link has
        caught up), samples are therefore kept, not stamped; then all of them
        are stamped with the caught-up clock and published. Nothing is lost,
        the first stamps are right, the catch-up costs latency only once.

        Parameters
        ----------
        board_us : ndarray of int64, shape (n,)
            Board time of each sample, us (unwrapped).
        values : ndarray of float64, shape (n, 3 N + 4)
            Each sensor's field (T), then the currents (A).
        host_ns : int
            Host time of the read, ns.
        """
        self._board_clock.observe(int(board_us[-1]), host_ns)
        if self._catching_up:
            self._held.append((board_us, values))
            held = sum(len(b) for b, _ in self._held)
            if len(board_us) > self._caught_up_records and held < MAX_HELD_RECORDS:
                return
            self._catching_up = False
            board_us = np.concatenate([b for b, _ in self._held])
            values = np.concatenate([v for _, v in self._held])
            self._held.clear()
        self._publish(self._board_clock.to_host(board_us), values)

    def _publish(self, stamps: np.ndarray, values: np.ndarray) -> None:
        """Publish n samples: stamps (n,) ns; values (n, 3 N + 4): each field (T), currents (A).

        Messages are serialised in one go (``SampleSerialiser``) and published
        as bytes; per sample, sensor fields first, then the currents.
        """
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
        self.counters['records'] += n

    # -- diagnostics ------------------------------------------------------------

    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        then, records, sent = self._rate_mark
        span = max(now - then, 1e-9)
        self._rate_mark = (now, self.counters['records'], self.counters['commands_sent'])
        stats = self._decoder.stats
        self.counters['resyncs'] = self._base['resyncs'] + stats.resyncs
        self.counters['dropped_bytes'] = self._base['dropped_bytes'] + stats.dropped_bytes
        if self.link_state != 'connected':
            level, message = DiagnosticStatus.ERROR, f'board link {self.link_state}'
        elif self._timed_out:
            level, message = DiagnosticStatus.WARN, 'command timeout: zero currents'
        else:
            level, message = DiagnosticStatus.OK, 'connected'
        values = {
            'link state': self.link_state,
            'firmware': self.config.firmware,
            'field kind': 'raw' if self._v2x else 'baseline and feedthrough removed (V4x)',
            'enabled': str(self._enabled),
            'records/s': f'{(self.counters["records"] - records) / span:.1f}',
            'command rate (1/s)': f'{(self.counters["commands_sent"] - sent) / span:.1f}',
            'applied PWM (counts)': ' '.join(str(int(c)) for c in self._applied),
            'last board message': self.last_info,
        }
        values.update({name.replace('_', ' '): str(v) for name, v in self.counters.items()})
        status = DiagnosticStatus(
            level=level,
            name=f'{NODE_NAME}: board link',
            message=message,
            hardware_id=self.config.port,
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)

    # -- shutdown ---------------------------------------------------------------

    def close(self) -> None:
        """Stop the I/O thread, send zero currents (V2x) and close the port (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._io.join(timeout=2.0)
        if self._v2x and self._link.is_open:
            with self._lock:
                self._send(_ZERO)
        self._link.close()

    def destroy_node(self) -> None:
        """Close the board link (zero currents first), then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the driver until SIGINT or SIGTERM.

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
