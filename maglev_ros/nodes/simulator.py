"""Simulator node: ``ros2 run maglev_ros simulator``.

The full nonlinear Maggy model of the physics core (:class:`~maglev_ros.physics.Simulator`)
on the shared topics (``docs/topics.md``), indistinguishable for the other
nodes from the board driver:

* ``maglev/sensor_<k>/field`` (sensor_msgs/MagneticField, T, frame
  ``maglev_sensor_<k>``) for each simulated sensor, stamped with the
  simulated sample time;
* ``maglev/currents`` (sensor_msgs/JointState, names x+ x- y+ y-, effort =
  coil current in A; published last per sample: it marks a complete sample);
* ``maglev/state/true`` (nav_msgs/Odometry: position, ZYX Euler angles as a
  quaternion, frame ``maglev_base``, child ``maglev_magnet``, twist in the
  child frame);
* ``/clock`` (rosgraph_msgs/Clock), the simulated time: of every sample in
  lockstep (the recorder logs lockstep messages at it), once per burst of
  samples in real time (every ``pace_period``, 1 ms by default: plenty for
  ``use_sim_time`` and a fifth of the publishing cost);
* ``maglev/markers`` (visualization_msgs/MarkerArray): base components and
  the magnet, for RViz, at ``marker_rate`` Hz of wall time;
* ``/diagnostics``: mode, run state, simulated time, real-time factor,
  commands, late commands, held samples, timeouts, crash reason/time/state.

It subscribes ``maglev/currents/command`` (sensor_msgs/JointState, effort: 4
currents in A). With ``coil_dynamics`` a command drives the coil model as the
board does: voltage = coil resistance x commanded current, clipped at the
supply, then the coils' L/R dynamics. Services: ``maglev/simulator/reset``
(std_srvs/Trigger) restarts from the initial state (and recovers a crash);
``maglev/simulator/pause`` (std_srvs/SetBool) pauses (true) or resumes.

Timing modes (``mode``; the pacing is a ROS-free
:class:`~maglev_ros.physics.session.SimulationSession`, which also states the
lockstep contract):

``realtime``
    A thread paced to the wall clock steps the model at ``sample_rate`` with
    the latest command (applied when it arrives), in bursts of
    ``pace_period`` s (default 1 ms = 5 samples; the board's driver also
    publishes in bursts). A command is *late* when
    at least one sample was stepped with the held command since the previous
    one; held samples and late commands are counted. If the node falls more
    than 0.1 s behind, the backlog is dropped and counted (``overruns``).
``lockstep``
    Sample k is published, then exactly one command is awaited for it;
    commands are taken in order (early ones queue). After ``command_timeout``
    s without a command the last one is held, the sample is stepped and the
    timeout counted. The first sample is published once a command publisher
    and ``start_subscribers`` subscribers of ``maglev/currents`` exist (and
    the node is not paused). Deterministic given ``seed``; as fast as the
    graph allows.

A crash (the magnet touches the base or leaves the workspace) stops the
integration; it is logged and reported on ``/diagnostics`` (ERROR) until a
reset. Simulated time keeps increasing across resets (a reset starts a new
run one sample after the last published one).

QoS: see :mod:`maglev_ros.nodes.contract` (sensor streams RELIABLE depth
1000; commands BEST_EFFORT depth 10 in real time, as the driver; RELIABLE
depth 1000 in lockstep, where no command may be lost).
"""

from __future__ import annotations

import math
import os
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, MagneticField
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from maglev_ros.nodes import contract, intra_process
from maglev_ros.nodes.markers import base_markers, magnet_marker, marker_array
from maglev_ros.nodes.messages import CommandMessageError, command_currents
from maglev_ros.nodes.params import (
    NodeParameterError,
    Param,
    ParameterTable,
    choice,
    integer,
    number,
)
from maglev_ros.physics import FIELD_MODELS, KINEMATICS, TORQUE_MODES, Simulator
from maglev_ros.physics.sample_encoder import SampleEncoder
from maglev_ros.physics.session import MODES, CommandError, SampleBatch, SimulationSession
from maglev_ros.physics.session_health import crash_line, session_health, timeout_line
from maglev_ros.physics.simulation import MAGNET_MODES
from maglev_ros.physics.simulator_config import SimulatorConfig, SimulatorConfigError
from maglev_ros.physics.simulator_config import make_simulator as _make_simulator
from maglev_ros.topics import SIMULATOR_PAUSE_SERVICE, SIMULATOR_RESET_SERVICE

__all__ = [
    'MODES',
    'SimulatorConfig',
    'SimulatorNode',
    'PARAMETERS',
    'SimulatorParameterError',
    'build_config',
    'make_simulator',
    'main',
]

NODE_NAME = 'maglev_simulator'
WARN_THROTTLE_S = 1.0  # s between repeated warnings of one kind


class SimulatorParameterError(NodeParameterError):
    """A simulator parameter has an invalid value."""


def _initial_state(name: str, state: tuple[float, ...]) -> tuple[float, ...] | None:
    if not state:
        return None
    if len(state) != 12 or not all(math.isfinite(v) for v in state):
        raise SimulatorParameterError(
            f'{name} must be 12 finite numbers (x y z alpha beta gamma vx vy vz '
            f'wx wy wz), got {list(state)}'
        )
    return state


def _sensor_indices(name: str, sensors: tuple[int, ...]) -> tuple[int, ...]:
    if any(k < 0 for k in sensors) or len(set(sensors)) != len(sensors):
        raise SimulatorParameterError(
            f'{name} must be distinct sensor indices >= 0, got {list(sensors)}'
        )
    return sensors


def _parameter_set(name: str, value: str) -> str:
    if not value:
        raise SimulatorParameterError(f'{name} must name a parameter set, got an empty string')
    return value


PARAMETERS = ParameterTable(
    NODE_NAME,
    SimulatorParameterError,
    {
        'params': Param(
            'maggy_v2', 'parameter set: maggy_v2, maggy_v4 or a YAML path', check=_parameter_set
        ),
        'field_model': Param(
            'fast', 'field model: fast, accurate or filament', check=choice(*FIELD_MODELS)
        ),
        'torque': Param('true', 'torque model: true or published', check=choice(*TORQUE_MODES)),
        'kinematics': Param('rigid', 'kinematics: rigid or published', check=choice(*KINEMATICS)),
        'sample_rate': Param(
            5000.0, 'samples per second, Hz (the board: 5000)', check=number(0, above=True)
        ),
        'substeps': Param(1, 'RK4 steps per sample', check=integer(1)),
        'magnet': Param(
            'free',
            'levitating magnet: free, fixed (held at the initial state) or absent',
            check=choice(*MAGNET_MODES),
        ),
        'initial_state': Param(
            [],
            '12 numbers x y z alpha beta gamma vx vy vz wx wy wz (m, rad, m/s, rad/s); '
            'empty: resting at the first equilibrium',
            kind='double_array',
            check=_initial_state,
        ),
        'coil_dynamics': Param(True, 'coil L/R electrics, voltage R i_cmd clipped at the supply'),
        'sensor_noise': Param(0.0, 'white sensor noise per axis, T rms', check=number(0)),
        'sensor_quantization': Param(
            0.0, 'sensor resolution, T per LSB (0: none)', check=number(0)
        ),
        'sensor_delay': Param(1, 'sensor delay in samples (the board has 1)', check=integer(0)),
        'seed': Param(0, 'seed of the sensor noise', check=integer(0)),
        'mode': Param(
            'realtime',
            'timing: realtime (wall clock) or lockstep (one command per sample)',
            check=choice(*MODES),
        ),
        'command_timeout': Param(
            1.0,
            'lockstep: s to wait for a command before holding the last one',
            check=number(0, above=True),
        ),
        'pace_period': Param(
            0.001,
            'realtime: s of wall time per burst of samples (0: every sample)',
            check=number(0),
        ),
        'start_paused': Param(
            False, f'start paused (resume with {SIMULATOR_PAUSE_SERVICE} false)'
        ),
        'start_subscribers': Param(
            0,
            f'subscribers of {contract.CURRENTS_TOPIC} to wait for at start (lockstep; '
            'real time with wait_for_controller)',
            check=integer(0),
        ),
        'wait_for_controller': Param(
            False,
            f'realtime: start only once a first {contract.COMMAND_TOPIC} arrived and '
            'start_subscribers subscribers exist (a free magnet waits for its controller)',
        ),
        'sensors': Param(
            [],
            'indices of the sensors to publish; empty: all',
            kind='integer_array',
            check=_sensor_indices,
        ),
        'publish_state': Param(True, f'publish the true state on {contract.TRUE_STATE_TOPIC}'),
        'publish_clock': Param(True, f'publish the simulated time on {contract.CLOCK_TOPIC}'),
        'marker_rate': Param(
            10.0, 'RViz markers per second of wall time (0: none)', check=number(0)
        ),
        'diagnostics_period': Param(
            1.0,
            f's between {contract.DIAGNOSTICS_TOPIC} messages',
            check=number(0, above=True),
        ),
    },
)
_PARAMETERS = PARAMETERS  # the name test_launch and older callers use


def build_config(values: dict) -> SimulatorConfig:
    """Validate raw parameter values and build a ``SimulatorConfig``.

    Parameters
    ----------
    values : dict
        Parameter name to value, as declared by ``SimulatorNode`` (None or
        empty for ``initial_state`` and ``sensors``: the default); a missing
        name takes its default.

    Returns
    -------
    SimulatorConfig

    Raises
    ------
    SimulatorParameterError
        Naming the first invalid parameter and its value.
    """
    return SimulatorConfig(**PARAMETERS.validate(values))


def make_simulator(cfg: SimulatorConfig) -> Simulator:
    """:func:`maglev_ros.physics.simulator_config.make_simulator`, its errors as the node's.

    Parameters
    ----------
    cfg : SimulatorConfig
        The validated parameters.
    """
    try:
        return _make_simulator(cfg)
    except SimulatorConfigError as err:
        raise SimulatorParameterError(str(err)) from err


class SimulatorNode(Node):
    """The simulator (see the module docstring): ROS wiring around a simulation session.

    The :class:`~maglev_ros.physics.session.SimulationSession` decides when
    samples are stepped and with which command; this node feeds it commands,
    service calls and time, and publishes the batches it returns. One lock
    serialises the session's calls and the publishing of their batches.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``, ``parameter_overrides``).

    Raises
    ------
    SimulatorParameterError
        If a parameter is invalid.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.config = cfg = build_config(PARAMETERS.declare(self))
        self.sim = make_simulator(cfg)
        self.session = SimulationSession(
            self.sim,
            cfg.mode,
            pace_period=cfg.pace_period,
            command_timeout=cfg.command_timeout,
            paused=cfg.start_paused,
        )
        n_all = len(self.sim.model.params.sensors)
        self.sensors = cfg.sensors or tuple(range(n_all))
        self._lock = threading.RLock()  # the session and the publishing of its batches

        qos = contract.SENSOR_QOS
        self._field_pubs = [
            self.create_publisher(MagneticField, contract.field_topic(k), qos)
            for k in self.sensors
        ]
        self._current_pub = self.create_publisher(JointState, contract.CURRENTS_TOPIC, qos)
        self._state_pub = self._clock_pub = None
        if cfg.publish_state:
            from nav_msgs.msg import Odometry

            self._state_pub = self.create_publisher(Odometry, contract.TRUE_STATE_TOPIC, qos)
        if cfg.publish_clock:
            self._clock_pub = self.create_publisher(Clock, contract.CLOCK_TOPIC, qos)
        self._diag_pub = self.create_publisher(
            DiagnosticArray, contract.DIAGNOSTICS_TOPIC, contract.DIAGNOSTICS_QOS
        )
        self._wire_publishing(cfg)
        # composed nodes of this process may take the samples directly (intra_process)
        self.samples_source = intra_process.Channel(self.sensors)
        self.samples_source.on_error = self._on_listener_error
        self._intra = [
            (self.resolve_topic_name(contract.CURRENTS_TOPIC), self.samples_source),
            (
                self.resolve_topic_name(contract.COMMAND_TOPIC),
                intra_process.CommandSink(
                    self._take_command, self._command_source_attached, self._lock
                ),
            ),
        ]
        for topic, obj in self._intra:
            intra_process.register(self.context, topic, obj)
        command_qos = (
            contract.LOCKSTEP_COMMAND_QOS if cfg.mode == 'lockstep' else contract.COMMAND_QOS
        )
        self._command_sub = self.create_subscription(
            JointState, contract.COMMAND_TOPIC, self._on_command, command_qos
        )
        self.create_service(Trigger, SIMULATOR_RESET_SERVICE, self._on_reset)
        self.create_service(SetBool, SIMULATOR_PAUSE_SERVICE, self._on_pause)
        self.create_timer(cfg.diagnostics_period, self.publish_diagnostics)
        if cfg.marker_rate > 0:
            self._marker_pub = self.create_publisher(
                MarkerArray, contract.MARKERS_TOPIC, contract.MARKERS_QOS
            )
            self._base_markers = base_markers(self.sim.model.params)
            self.create_timer(1.0 / cfg.marker_rate, self.publish_markers)
        self._stop = threading.Event()
        self._closed = False
        self._thread = None
        if cfg.mode == 'lockstep':
            self.create_timer(min(0.05, cfg.command_timeout / 4), self._lockstep_watch)
        else:
            if not cfg.wait_for_controller:
                self._publish(self.session.start(time.monotonic()))
            self._thread = threading.Thread(
                target=self._realtime_loop, name='maglev-simulator', daemon=True
            )
            self._thread.start()
        p = self.sim.model.params
        self.get_logger().info(
            f'{p.name} ({cfg.field_model} field), magnet {cfg.magnet}, {cfg.mode} at '
            f'{cfg.sample_rate:g} Hz, sensors {list(self.sensors)}, coil dynamics '
            f'{"on" if cfg.coil_dynamics else "off"}, sensor delay {cfg.sensor_delay}, '
            f'noise {cfg.sensor_noise:g} T, seed {cfg.seed}'
            f'{", paused" if self.paused else ""}'
        )

    # -- run state (the session's) ----------------------------------------------

    @property
    def counters(self) -> dict[str, int]:
        """The session's counters (samples, commands, late commands, timeouts, ...)."""
        return self.session.counters

    @property
    def currents_subscribers(self) -> int:
        """Subscriptions matched to this node's ``maglev/currents`` publisher.

        The currents message ends each sample (a lockstep excitation answers
        it with the next command; a recorder counts samples by it), so this is
        the readiness to wait on before stepping; lockstep starts once it
        reaches ``start_subscribers``. Listeners of this process that take
        the samples directly (:mod:`~maglev_ros.nodes.intra_process`) count too.
        """
        return self._current_pub.get_subscription_count() + self.samples_source.listeners

    @property
    def command_publishers(self) -> int:
        """Publishers matched to this node's ``maglev/currents/command`` subscription.

        Discovery is matched from each side separately: a command publisher may
        see this subscription before this subscription sees it, and a command
        sent in between is lost (a lockstep timeout). Wait on both sides. A
        controller of this process attached directly counts as one.
        """
        if self._command_sub is None:  # intra_process: the attached controller
            return 1
        return self._command_sub.get_publisher_count()

    @property
    def paused(self) -> bool:
        """Whether stepping is paused."""
        return self.session.paused

    @property
    def started(self) -> bool:
        """Whether the first sample was published (lockstep waits for the graph)."""
        return self.session.started

    @property
    def last_stamp_ns(self) -> int:
        """Simulated time of the last published sample, ns (-1 before any)."""
        return self.session.last_stamp_ns

    @property
    def real_time_factor(self) -> float:
        """Simulated over wall time between the last two diagnostics (NaN at first)."""
        return self.session.real_time_factor

    # -- publishing -------------------------------------------------------------

    def _wire_publishing(self, cfg: SimulatorConfig) -> None:
        """Build the sample encoder and bind each of its messages to its publisher.

        Pre-serialised bytes go straight to the publishers' handles: they are
        safe to use from the stepping thread because the node destroys its
        publishers only after :meth:`close` joined it.
        """
        clock = 'none' if self._clock_pub is None else 'sample'
        if clock == 'sample' and cfg.mode != 'lockstep':
            clock = 'burst'  # real time: /clock once per burst
        self._encoder = SampleEncoder(
            self.sensors, self._state_pub is not None, clock, self.session.burst
        )
        pubs = dict(zip(map(contract.field_topic, self.sensors), self._field_pubs, strict=True))
        pubs[contract.TRUE_STATE_TOPIC] = self._state_pub
        pubs[contract.CURRENTS_TOPIC] = self._current_pub
        pubs[contract.CLOCK_TOPIC] = self._clock_pub
        self._publish_calls = [pubs[topic].handle.publish_raw for topic in self._encoder.topics]
        self._sample_pubs = [pubs[topic] for topic in self._encoder.topics]
        # the same bytes for composed recorders and identifiers (intra_process taps)
        self._taps = [
            intra_process.tap(self.context, self.resolve_topic_name(topic))
            for topic in self._encoder.topics
        ]
        self._clock_tap = None
        if self._clock_pub is not None:
            self._publish_clock = self._clock_pub.handle.publish_raw
            if clock == 'burst':
                self._clock_tap = intra_process.tap(
                    self.context, self.resolve_topic_name(contract.CLOCK_TOPIC)
                )
        classes = [pub.msg_type for pub in self._sample_pubs]
        if self._clock_tap is not None:
            classes.append(self._clock_pub.msg_type)
        for tap, cls in zip(self._own_taps(), classes, strict=True):
            tap.add_publisher(cls)
            tap.on_error = self._on_listener_error

    def _own_taps(self) -> list:
        return self._taps + ([self._clock_tap] if self._clock_tap is not None else [])

    def _publish(self, batch: SampleBatch | None) -> None:
        """Publish a batch of samples (lockstep: usually one); report a crash.

        Real time: the ``/clock`` messages of the batch (one per burst) go
        first. The samples' messages are serialised in one go and published
        sample by sample.
        """
        if batch is None:
            return
        n = len(batch)
        if n:
            clocks = self._encoder.clock_messages(batch)
            for message in clocks:
                self._publish_clock(message)
            if clocks and self._clock_tap.listeners:
                self._clock_tap.deliver(clocks)
            # a topic nobody subscribes to is neither serialised nor published
            # (volatile: no subscriber joining later could get the message; a composed
            # estimator that takes the samples in this process leaves the fields and
            # the currents without any)
            active = self._active_topics()
            tapped = tuple(tap.listeners > 0 for tap in self._taps)
            if any(tapped):
                self._publish_tapped(batch, active, tapped)
            else:
                messages = self._encoder.sample_messages(batch, active)
                calls = [c for c, a in zip(self._publish_calls, active, strict=True) if a]
                for publish, message in zip(calls * n, messages, strict=True):
                    publish(message)
            if self.samples_source.listeners:
                self.samples_source.deliver(batch)
        if batch.crashed:
            self._on_crash()

    def _publish_tapped(self, batch: SampleBatch, active, tapped) -> None:
        """Publish a batch to the middleware's subscribers and hand it to the taps' listeners.

        The middleware gets the messages sample after sample (as without taps);
        each tap gets its topic's messages of the batch as one list.
        """
        wanted = tuple(a or t for a, t in zip(active, tapped, strict=True))
        messages = self._encoder.sample_messages(batch, wanted)
        k = sum(wanted)
        position = {}
        for i, w in enumerate(wanted):
            if w:
                position[i] = len(position)
        published = [(self._publish_calls[i], position[i]) for i, a in enumerate(active) if a]
        if published:
            for start in range(0, len(messages), k):
                for publish, j in published:
                    publish(messages[start + j])
        for i, t in enumerate(tapped):
            if t:
                self._taps[i].deliver(messages[position[i] :: k])

    def _active_topics(self) -> tuple[bool, ...]:
        """Return which sample topics have subscribers now.

        Asked each batch: a subscriber that just matched gets every sample from
        the first, as a test or a recorder expects.
        """
        return tuple(pub.get_subscription_count() > 0 for pub in self._sample_pubs)

    def _on_listener_error(self, name: str, err: Exception) -> None:
        self.get_logger().error(
            f'{name}: samples not taken in this process: {err}', throttle_duration_sec=1.0
        )

    def publish_markers(self) -> None:
        """Publish the base and the magnet (at its latest state) as RViz markers."""
        markers = list(self._base_markers)
        if self.config.magnet != 'absent':
            params, state = self.sim.model.params, self.session.last_state
            markers.append(magnet_marker(params, state, self.sim.crashed))
        self._marker_pub.publish(marker_array(markers, max(self.last_stamp_ns, 0)))

    def publish_diagnostics(self) -> None:
        """Publish the run state and counters on ``/diagnostics``."""
        if not self.context.ok():  # a signal is shutting the node down
            return
        self.session.measure_real_time_factor(time.monotonic())
        health = session_health(self.session, self.config.magnet)
        self._diag_pub.publish(
            contract.diagnostic_array(
                self.get_clock().now().nanoseconds,  # the node's clock: sim time under it
                f'{NODE_NAME}: simulation',
                health.level,
                health.message,
                health.values,
                hardware_id='simulator',
            )
        )

    def _on_crash(self) -> None:
        self.get_logger().error(crash_line(self.session))
        self.publish_diagnostics()

    # -- stepping ---------------------------------------------------------------

    def _on_command(self, msg: JointState) -> None:
        try:
            currents = command_currents(msg)
        except CommandMessageError as err:
            self.get_logger().warning(f'rejected command: {err}', throttle_duration_sec=1.0)
            return
        self._take_command(currents)

    def _command_source_attached(self, name: str) -> None:
        """Drop the command subscription: a controller of this process sends them directly."""
        self.destroy_subscription(self._command_sub)
        self._command_sub = None
        with self._lock:  # the loop is closed in this thread: each burst is answered first
            self.session.max_batch = self.session.burst
        self.get_logger().info(f'commands from {name} in this process (intra_process)')

    def _take_command(self, values) -> None:
        """Apply one command (from the subscription or a controller of this process)."""
        with self._lock:
            try:
                batch = self.session.command(values, time.monotonic())
            except CommandError as err:
                self.get_logger().warning(
                    f'rejected command: {err}', throttle_duration_sec=WARN_THROTTLE_S
                )
                return
            self._publish(batch)

    def _lockstep_watch(self) -> None:
        """Lockstep: start when the graph is ready; hold the command on a timeout."""
        with self._lock:
            session = self.session
            if session.paused or session.crashed:
                return
            now = time.monotonic()
            if not session.started:
                if self._graph_ready():
                    self._publish(session.start(now))
                return
            age = now - session.waiting_since
            batch = session.check_timeout(now)
            if batch is not None:
                self.get_logger().warning(
                    timeout_line(session, age), throttle_duration_sec=WARN_THROTTLE_S
                )
                self._publish(batch)

    def _graph_ready(self) -> bool:
        """Return True once a command publisher and the currents subscribers exist."""
        return (
            self.count_publishers(contract.COMMAND_TOPIC) >= 1
            and self.currents_subscribers >= self.config.start_subscribers
        )

    def _realtime_loop(self) -> None:
        if not self.session.started:  # wait_for_controller
            self.get_logger().info(f'waiting for a first command on {contract.COMMAND_TOPIC}')
            while not self._stop.wait(0.01):
                try:
                    ready = self._graph_ready() and self.counters['commands'] > 0
                except Exception:  # the context shut down (signal) while waiting
                    if self.context.ok() and not self._stop.is_set():
                        raise
                    return
                if ready:
                    with self._lock:
                        self._publish(self.session.start(time.monotonic()))
                    self.get_logger().info('controller found: stepping in real time')
                    break
        while not self._stop.is_set():
            now = time.monotonic()
            try:
                with self._lock:
                    batch, wait = self.session.pace(now)
                    self._publish(batch)
            except Exception:  # publishing fails once the context shuts down (signal)
                if self.context.ok() and not self._stop.is_set():
                    raise
                return
            # one wake-up per burst: sleep to the next one now, not after another
            # pace() call (a second wake-up per burst cost ~15 us per sample). Behind
            # (no wait), still give up the GIL between bursts: a pause or reset
            # service waiting for the lock in the executor's thread gets it at once
            # (measured on a loaded machine: without this a pause call waited > 30 s)
            time.sleep(max(wait - (time.monotonic() - now), 0.0))

    # -- services ---------------------------------------------------------------

    def reset(self) -> str:
        """Restart from the initial state (recovers a crash); return a description."""
        with self._lock:
            self._publish(self.session.reset(time.monotonic()))
            start_ns = self.session.run_start_ns
        message = f'reset: new run starts at {start_ns * 1e-9:.6f} s'
        self.get_logger().info(message)
        return message

    def set_paused(self, paused: bool) -> None:
        """Pause (True) or resume (False) the integration.

        Parameters
        ----------
        paused : bool
            True pauses, False resumes.
        """
        with self._lock:
            self._publish(self.session.set_paused(paused, time.monotonic()))

    def pause_after(self, index: int | None) -> None:
        """Pause by itself once the run's sample ``index`` was stepped (None: never).

        Lockstep: exactly the samples up to ``index`` are published, the
        commands after them queue until :meth:`set_paused` resumes
        (:meth:`~maglev_ros.physics.session.SimulationSession.pause_after`).

        Parameters
        ----------
        index : int or None
            Index of a sample of the current run (sample 0 is its first).
        """
        with self._lock:
            self.session.pause_after(index)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response):
        response.message = self.reset()
        response.success = True
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response):
        self.set_paused(request.data)
        response.success = True
        response.message = 'paused' if self.paused else 'running'
        self.get_logger().info(f'simulation {response.message}')
        return response

    # -- shutdown ---------------------------------------------------------------

    def close(self) -> None:
        """Stop the real-time thread (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        for topic, obj in self._intra:
            intra_process.unregister(self.context, topic, obj)
        for tap in self._own_taps():
            tap.remove_publisher()

    def destroy_node(self) -> None:
        """Stop stepping, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the simulator until SIGINT, SIGTERM or SIGHUP.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    # Fast DDS sends from its own thread: the stepping thread does not wait for
    # the transport (measured: real-time factor 0.9 -> 1.0 at 5 kHz with a
    # recorder in another process, benchmarks/lab.py). Override in the environment.
    os.environ.setdefault('RMW_FASTRTPS_PUBLICATION_MODE', 'ASYNCHRONOUS')
    return contract.run_nodes(
        [SimulatorNode], args, NODE_NAME, (SimulatorParameterError,), PARAMETERS
    )


if __name__ == '__main__':
    raise SystemExit(main())
