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

It subscribes ``maglev/currents/command`` (std_msgs/Float64MultiArray, 4
currents in A). With ``coil_dynamics`` a command drives the coil model as the
board does: voltage = coil resistance x commanded current, clipped at the
supply, then the coils' L/R dynamics. Services: ``maglev/simulator/reset``
(std_srvs/Trigger) restarts from the initial state (and recovers a crash);
``maglev/simulator/pause`` (std_srvs/SetBool) pauses (true) or resumes.

Timing modes (``mode``):

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
from collections import deque
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Pose
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import ColorRGBA, Float64MultiArray
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import Marker, MarkerArray

from maglev_ros.nodes import contract
from maglev_ros.nodes.cdr_batch import RawMessageBatch, SampleSerialiser
from maglev_ros.nodes.params import (
    NodeParameterError,
    Param,
    ParameterTable,
    choice,
    integer,
    number,
)
from maglev_ros.physics import (
    FIELD_MODELS,
    KINEMATICS,
    TORQUE_MODES,
    CoilDynamics,
    ParameterError,
    SensorEffects,
    Simulator,
    make_model,
)
from maglev_ros.physics.kernels import odometry_values
from maglev_ros.physics.simulation import MAGNET_MODES
from maglev_ros.topics import SIMULATOR_PAUSE_SERVICE, SIMULATOR_RESET_SERVICE

__all__ = [
    'MODES',
    'SimulatorConfig',
    'SimulatorNode',
    'PARAMETERS',
    'SimulatorParameterError',
    'base_markers',
    'build_config',
    'make_simulator',
    'main',
]

NODE_NAME = 'maglev_simulator'
MODES = ('realtime', 'lockstep')
WARN_THROTTLE_S = 1.0  # s between repeated warnings of one kind
MAX_BACKLOG_S = 0.1  # s of wall time the real-time loop may catch up at most
_ZERO = np.zeros(4)


class SimulatorParameterError(NodeParameterError):
    """A simulator parameter has an invalid value."""


@dataclass(frozen=True)
class SimulatorConfig:
    """Validated simulator parameters (meanings: ``_PARAMETERS`` below).

    Attributes
    ----------
    params : str
        Parameter set: ``maggy_v2``, ``maggy_v4`` or a YAML path.
    field_model, torque, kinematics : str
        Model options.
    sample_rate : float
        Hz.
    substeps : int
        RK4 steps per sample.
    magnet : str
        ``free``, ``fixed`` or ``absent``.
    initial_state : tuple of float or None
        12 numbers, or None for the first equilibrium.
    coil_dynamics : bool
        Coil L/R electrics with the supply limit.
    sensor_noise, sensor_quantization : float
        T rms and T per LSB.
    sensor_delay : int
        Samples of sensor delay.
    seed : int
        Noise seed.
    mode : str
        ``realtime`` or ``lockstep``.
    command_timeout : float
        Lockstep: s to wait for a sample's command.
    pace_period : float
        Real time: s of wall time between bursts of samples.
    start_paused : bool
        Start paused (resume with the pause service).
    start_subscribers : int
        Lockstep: subscribers of ``maglev/currents`` to wait for.
    sensors : tuple of int
        Indices of the parameter set's sensors to publish.
    publish_state, publish_clock : bool
        Publish the true state and ``/clock``.
    marker_rate : float
        Hz of wall time (0: no markers).
    diagnostics_period : float
        s between diagnostics messages.
    """

    params: str
    field_model: str
    torque: str
    kinematics: str
    sample_rate: float
    substeps: int
    magnet: str
    initial_state: tuple[float, ...] | None
    coil_dynamics: bool
    sensor_noise: float
    sensor_quantization: float
    sensor_delay: int
    seed: int
    mode: str
    command_timeout: float
    pace_period: float
    start_paused: bool
    start_subscribers: int
    sensors: tuple[int, ...]
    publish_state: bool
    publish_clock: bool
    marker_rate: float
    diagnostics_period: float


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
            f'lockstep: subscribers of {contract.CURRENTS_TOPIC} to wait for at start',
            check=integer(0),
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
    """Build the physics simulator of a configuration.

    Raises
    ------
    SimulatorParameterError
        If the parameter set cannot be loaded or the options do not fit it.
    """
    try:
        model = make_model(
            cfg.params, field=cfg.field_model, torque=cfg.torque, kinematics=cfg.kinematics
        )
    except (ParameterError, OSError, ValueError) as err:
        raise SimulatorParameterError(f'params {cfg.params!r}: {err}') from err
    n_sensors = len(model.params.sensors)
    bad = [k for k in cfg.sensors if k >= n_sensors]
    if bad:
        raise SimulatorParameterError(
            f'sensors must be indices below {n_sensors} ({model.params.name} has {n_sensors} '
            f'sensors), got {list(cfg.sensors)}'
        )
    coil = CoilDynamics.from_parameters(model.params) if cfg.coil_dynamics else None
    sensor = SensorEffects(
        noise_rms=cfg.sensor_noise,
        quantization=cfg.sensor_quantization,
        delay_samples=cfg.sensor_delay,
    )
    try:
        return Simulator(
            model,
            cfg.sample_rate,
            substeps=cfg.substeps,
            coil=coil,
            sensor=sensor,
            seed=cfg.seed,
            x0=cfg.initial_state,
            magnet=cfg.magnet,
        )
    except ValueError as err:
        raise SimulatorParameterError(f'initial_state / model: {err}') from err


def _color(r: float, g: float, b: float, a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=r, g=g, b=b, a=a)


def base_markers(params) -> list[Marker]:
    """Cylinder markers of the solenoids (copper) and permanent magnets (grey)."""
    markers = []
    groups = (
        (params.solenoids, 'solenoids', _color(0.8, 0.45, 0.2)),
        (params.permanent_magnets, 'permanent_magnets', _color(0.5, 0.5, 0.55)),
    )
    for cyl, ns, color in groups:
        for i in range(cyl.count):
            m = Marker(ns=ns, id=i, type=Marker.CYLINDER, action=Marker.ADD, color=color)
            m.header.frame_id = contract.BASE_FRAME
            c = cyl.centers[i]
            m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in c)
            m.pose.orientation.w = 1.0
            m.scale.x = m.scale.y = 2.0 * float(cyl.radius[i])
            m.scale.z = float(cyl.length[i])
            markers.append(m)
    return markers


class SimulatorNode(Node):
    """The simulator (see the module docstring).

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
        n_all = len(self.sim.model.params.sensors)
        self.sensors = cfg.sensors or tuple(range(n_all))
        self._columns = np.array([3 * k + j for k in self.sensors for j in range(3)])
        self._dt_ns = 1e9 / cfg.sample_rate
        self._lock = threading.RLock()  # simulator, command and run state
        self.counters = dict.fromkeys(
            (
                'samples',
                'commands',
                'commands_rejected',
                'late_commands',
                'held_samples',
                'timeouts',
                'overruns',
                'crashes',
                'resets',
            ),
            0,
        )
        self._command = _ZERO.copy()  # the command held for the next step
        self._queue: deque[np.ndarray] = deque()  # lockstep: commands not yet used
        self._steps_since_command = 0
        self._got_command = False
        self.paused = cfg.start_paused
        self.started = cfg.mode == 'realtime'
        self._wait_since = 0.0  # lockstep: monotonic time the last sample was published
        self._offset_ns = 0  # simulated time of the current run's sample 0
        self.last_stamp_ns = -1
        self._crash_reported = False
        self._rate_mark = (time.monotonic(), 0)
        self.real_time_factor = float('nan')

        # publishers: raw CDR templates, published as bytes
        qos = contract.SENSOR_QOS
        self._field_pubs = [
            self.create_publisher(MagneticField, contract.field_topic(k), qos)
            for k in self.sensors
        ]
        self._field_raw = [contract.field_template(k) for k in self.sensors]
        self._current_pub = self.create_publisher(JointState, contract.CURRENTS_TOPIC, qos)
        self._current_raw = contract.currents_template()
        self._state_pub = self._clock_pub = None
        if cfg.publish_state:
            from nav_msgs.msg import Odometry

            self._state_pub = self.create_publisher(Odometry, contract.TRUE_STATE_TOPIC, qos)
            self._state_raw = contract.odometry_template()
        if cfg.publish_clock:
            self._clock_pub = self.create_publisher(Clock, contract.CLOCK_TOPIC, qos)
            self._clock_raw = contract.clock_template()
        # samples per /clock message: each one in lockstep, one per burst in real time
        self._clock_stride = (
            1 if cfg.mode == 'lockstep' else max(1, int(round(cfg.pace_period * cfg.sample_rate)))
        )
        self._diag_pub = self.create_publisher(
            DiagnosticArray, contract.DIAGNOSTICS_TOPIC, contract.DIAGNOSTICS_QOS
        )
        command_qos = (
            contract.LOCKSTEP_COMMAND_QOS if cfg.mode == 'lockstep' else contract.COMMAND_QOS
        )
        self.create_subscription(
            Float64MultiArray, contract.COMMAND_TOPIC, self._on_command, command_qos
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
        self._last_state = self.sim.state
        self._odom_cache: list[float] = []
        self._odom_state = b''  # bytes of the state _odom_cache was computed for
        self._field_handles = [pub.handle for pub in self._field_pubs]
        self._current_handle = self._current_pub.handle
        self._state_handle = None if self._state_pub is None else self._state_pub.handle
        self._clock_handle = None if self._clock_pub is None else self._clock_pub.handle
        # real time: a burst of samples serialised at once, published sample by sample
        layouts = [contract.field_layout(contract.sensor_frame(k)) for k in self.sensors]
        publishers = list(self._field_handles)
        if self._state_handle is not None:
            layouts.append(contract.odometry_layout())
            publishers.append(self._state_handle)
        layouts.append(contract.currents_layout())
        publishers.append(self._current_handle)
        self._burst_serialiser = SampleSerialiser([RawMessageBatch(x) for x in layouts])
        # load its compiled kernel now, not in the stepping thread (up to 1 s the first time)
        self._burst_serialiser.serialise(
            np.zeros(1, np.int64), np.zeros((1, self._burst_serialiser.n_values))
        )
        self._burst_publishers = [handle.publish_raw for handle in publishers]
        self._first_reading = self.sim.reset()
        self._stop = threading.Event()
        self._closed = False
        self._thread = None
        if cfg.mode == 'lockstep':
            self.create_timer(min(0.05, cfg.command_timeout / 4), self._lockstep_watch)
        else:
            self._publish_sample(self._first_reading)
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

    # -- publishing -------------------------------------------------------------

    def _publish_sample(self, reading: np.ndarray) -> None:
        """Publish the current sample: clock, fields, true state, then currents.

        Pre-serialised bytes go straight to the publishers' handles (as the
        driver does): the handles are safe to use here because the node
        destroys its publishers only after :meth:`close` joined the stepping
        thread. The true state's 13 values are recomputed only when the state
        changed (never with the magnet fixed or absent).
        """
        sim = self.sim
        t_ns = self._offset_ns + int(round(sim.samples * self._dt_ns))
        if self._clock_pub is not None and sim.samples % self._clock_stride == 0:
            self._clock_handle.publish_raw(self._clock_raw.serialise(t_ns))
        values = reading[self._columns].tolist()
        for k, (handle, raw) in enumerate(zip(self._field_handles, self._field_raw, strict=True)):
            handle.publish_raw(raw.serialise(t_ns, values[3 * k : 3 * k + 3]))
        state = sim.state
        if self._state_pub is not None:
            key = state.tobytes()  # cheaper than np.array_equal at 5 kHz
            if key != self._odom_state:
                self._odom_cache = odometry_values(state).tolist()
                self._odom_state = key
            self._state_handle.publish_raw(self._state_raw.serialise(t_ns, self._odom_cache))
        self._last_state = state
        self._current_handle.publish_raw(self._current_raw.serialise(t_ns, sim.currents.tolist()))
        self.last_stamp_ns = t_ns
        self.counters['samples'] += 1

    def publish_markers(self) -> None:
        """Publish the base and the magnet (at its latest state) as RViz markers."""
        markers = list(self._base_markers)
        stamp_ns = max(self.last_stamp_ns, 0)
        if self.config.magnet != 'absent':
            m = self.sim.model.params.magnet
            magnet = Marker(
                ns='magnet',
                id=0,
                type=Marker.CYLINDER,
                action=Marker.ADD,
                color=_color(0.85, 0.1, 0.1) if not self.sim.crashed else _color(0.3, 0.3, 0.3),
            )
            magnet.header.frame_id = contract.BASE_FRAME
            v = odometry_values(self._last_state)
            magnet.pose = Pose()
            magnet.pose.position.x, magnet.pose.position.y, magnet.pose.position.z = v[0:3]
            o = magnet.pose.orientation
            o.x, o.y, o.z, o.w = v[3:7]
            magnet.scale.x = magnet.scale.y = 2.0 * m.radius
            magnet.scale.z = m.thickness
            markers.append(magnet)
        sec, nanosec = contract.split_stamp(stamp_ns)
        for marker in markers:
            marker.header.stamp.sec, marker.header.stamp.nanosec = sec, nanosec
        self._marker_pub.publish(MarkerArray(markers=markers))

    def publish_diagnostics(self) -> None:
        """Publish the run state and counters on ``/diagnostics``."""
        if not self.context.ok():  # a signal is shutting the node down
            return
        now = time.monotonic()
        then, samples = self._rate_mark
        self._rate_mark = (now, self.counters['samples'])
        if self.started and not self.paused and not self.sim.crashed:
            self.real_time_factor = (
                (self.counters['samples'] - samples) * self._dt_ns * 1e-9 / max(now - then, 1e-9)
            )
        sim = self.sim
        if sim.crashed:
            level = DiagnosticStatus.ERROR
            message = f'crashed at t = {sim.crash_time:.4f} s: {sim.reason}; reset to recover'
        elif self.paused:
            level, message = DiagnosticStatus.OK, 'paused'
        elif not self.started:
            level, message = DiagnosticStatus.OK, 'waiting for the command publisher'
        else:
            level, message = DiagnosticStatus.OK, f'running ({self.config.mode})'
        values = {
            'mode': self.config.mode,
            'magnet': self.config.magnet,
            'parameter set': sim.model.params.name,
            'simulated time (s)': f'{sim.time:.6f}',
            'real-time factor': f'{self.real_time_factor:.3f}',
            'crash reason': sim.reason,
            'crash time (s)': '' if sim.crash_time is None else f'{sim.crash_time:.6f}',
            'crash state': (
                '' if sim.crash_state is None else ' '.join(f'{v:.6g}' for v in sim.crash_state)
            ),
        }
        values.update({name.replace('_', ' '): v for name, v in self.counters.items()})
        self._diag_pub.publish(
            contract.diagnostic_array(
                time.time_ns(),
                f'{NODE_NAME}: simulation',
                level,
                message,
                values,
                hardware_id='simulator',
            )
        )

    # -- stepping ---------------------------------------------------------------

    def _step(self, command: np.ndarray) -> bool:
        """Step one sample with ``command`` and publish it; False after a crash."""
        reading = self.sim.step(command)
        if self.sim.crashed:
            self._on_crash()
            return False
        self._publish_sample(reading)
        return True

    def _step_burst(self, count: int) -> int:
        """Real time: step up to ``count`` samples with the held command, publish them.

        The caller holds the lock, so a command or a reset arriving meanwhile
        takes effect from the next burst on; the samples are published
        together (one serialisation, then the messages sample by sample).

        Returns
        -------
        int
            The number of samples stepped (``count`` unless paused or crashed).
        """
        sim = self.sim
        indices, readings, states, currents = [], [], [], []
        crashed = False
        for _ in range(count):
            if self.paused or sim.crashed:
                break
            if self._got_command and self._steps_since_command >= 1:
                self.counters['held_samples'] += 1
            self._steps_since_command += 1
            reading = sim.step(self._command)
            if sim.crashed:
                crashed = True
                break
            indices.append(sim.samples)
            readings.append(reading)
            states.append(sim.state)
            currents.append(sim.currents)
        if indices:
            self._publish_burst(indices, np.array(readings), states, np.array(currents))
        if crashed:
            self._on_crash()
        return len(indices) + crashed

    def _publish_burst(
        self,
        indices: list[int],
        readings: np.ndarray,
        states: list[np.ndarray],
        currents: np.ndarray,
    ) -> None:
        """Publish n samples at once, the messages :meth:`_publish_sample` would publish.

        Parameters
        ----------
        indices : list of int, length n
            Sample numbers (``Simulator.samples`` after each step).
        readings : ndarray, shape (n, 3 k_all)
            Sensor readings, T.
        states : list of ndarray, shape (12,) each
            States after each step.
        currents : ndarray, shape (n, 4)
            Coil currents, A.

        The ``/clock`` messages of the burst go first; the rest is serialised
        in one go and published sample by sample.
        """
        n = len(indices)
        stamps = self._offset_ns + np.rint(np.array(indices) * self._dt_ns).astype(np.int64)
        if self._clock_pub is not None:
            for index, t_ns in zip(indices, stamps.tolist(), strict=True):
                if index % self._clock_stride == 0:
                    self._clock_handle.publish_raw(self._clock_raw.serialise(t_ns))
        values = [readings[:, self._columns]]  # each published sensor's x y z, in order
        if self._state_pub is not None:
            odometry = np.empty((n, 13))
            for i, state in enumerate(states):
                key = state.tobytes()  # cheaper than np.array_equal at 5 kHz
                if key != self._odom_state:
                    self._odom_cache = odometry_values(state).tolist()
                    self._odom_state = key
                odometry[i] = self._odom_cache
            values.append(odometry)
        values.append(currents)
        messages = self._burst_serialiser.serialise(stamps, values)
        for publish, message in zip(self._burst_publishers * n, messages, strict=True):
            publish(message)
        self._last_state = states[-1]
        self.last_stamp_ns = int(stamps[-1])
        self.counters['samples'] += n

    def _on_crash(self) -> None:
        sim = self.sim
        self.counters['crashes'] += 1
        self._last_state = sim.crash_state
        state = ' '.join(f'{v:.4g}' for v in sim.crash_state[:6])
        self.get_logger().error(
            f'magnet crashed at t = {sim.crash_time:.4f} s ({sim.reason}); pose {state}; '
            f'integration stopped: call {SIMULATOR_RESET_SERVICE}'
        )
        self.publish_diagnostics()

    def _on_command(self, msg: Float64MultiArray) -> None:
        values = np.asarray(msg.data, dtype=float)
        if values.shape != (4,) or not np.all(np.isfinite(values)):
            self.counters['commands_rejected'] += 1
            self.get_logger().warning(
                f'rejected command: need 4 finite currents (x+, x-, y+, y-), got '
                f'{values.tolist()}',
                throttle_duration_sec=WARN_THROTTLE_S,
            )
            return
        with self._lock:
            self.counters['commands'] += 1
            if self.config.mode == 'realtime':
                if self._steps_since_command > 1:
                    self.counters['late_commands'] += 1
                self._steps_since_command = 0
                self._got_command = True
                self._command = values
                return
            if not self.started:
                return  # before the first sample: not a command for any sample
            self._queue.append(values)
            self._advance()

    def _advance(self) -> None:
        """Lockstep: step once per queued command while running."""
        while self._queue and not self.paused and not self.sim.crashed:
            self._command = self._queue.popleft()
            self._step(self._command)
        self._wait_since = time.monotonic()

    def _lockstep_watch(self) -> None:
        """Lockstep: start when the graph is ready; hold the command on a timeout."""
        with self._lock:
            if self.paused or self.sim.crashed:
                return
            if not self.started:
                if (
                    self.count_publishers(contract.COMMAND_TOPIC) >= 1
                    and self._current_pub.get_subscription_count() >= self.config.start_subscribers
                ):
                    self._start_run()
                return
            age = time.monotonic() - self._wait_since
            if age > self.config.command_timeout:
                self.counters['timeouts'] += 1
                self.get_logger().warning(
                    f'no command for {age:.3f} s > {self.config.command_timeout} s at '
                    f't = {self.sim.time:.6f} s: holding the last command',
                    throttle_duration_sec=WARN_THROTTLE_S,
                )
                self._step(self._command)
                self._wait_since = time.monotonic()

    def _start_run(self) -> None:
        self.started = True
        self._publish_sample(self._first_reading)
        self._wait_since = time.monotonic()

    def _realtime_loop(self) -> None:
        dt = 1.0 / self.config.sample_rate
        # samples stepped per wake-up: waking 5000 times a second costs more
        # than the step itself; the board's driver also publishes in bursts
        burst = max(1, int(round(self.config.pace_period / dt)))
        base, done = time.monotonic(), 0  # pacing origin and samples since it
        while not self._stop.is_set():
            with self._lock:
                running = not self.paused and not self.sim.crashed
            if not running:
                self._stop.wait(0.01)
                base, done = time.monotonic(), 0
                continue
            now = time.monotonic()
            due = int((now - base) / dt) - done
            if due < burst:
                time.sleep(max(base + (done + burst) * dt - now, 0.0))
                continue
            if due * dt > MAX_BACKLOG_S:
                self.counters['overruns'] += 1
                base, done = now - dt, 0
                due = 1
            try:
                with self._lock:
                    done += self._step_burst(due)
            except Exception:  # publishing fails once the context shuts down (signal)
                if self.context.ok() and not self._stop.is_set():
                    raise
                return

    # -- services ---------------------------------------------------------------

    def reset(self) -> str:
        """Restart from the initial state (recovers a crash); return a description."""
        with self._lock:
            self._offset_ns = self.last_stamp_ns + int(round(self._dt_ns))
            self._first_reading = self.sim.reset()
            self._queue.clear()
            self._command = _ZERO.copy()
            self._steps_since_command = 0
            self._got_command = False
            self.counters['resets'] += 1
            self._last_state = self.sim.state
            if self.started:
                self._publish_sample(self._first_reading)
                self._wait_since = time.monotonic()
        message = f'reset: new run starts at {self._offset_ns * 1e-9:.6f} s'
        self.get_logger().info(message)
        return message

    def set_paused(self, paused: bool) -> None:
        """Pause (True) or resume (False) the integration."""
        with self._lock:
            self.paused = bool(paused)
            if not self.paused and self.started and self.config.mode == 'lockstep':
                self._advance()

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

    def destroy_node(self) -> None:
        """Stop stepping, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the simulator until SIGINT or SIGTERM.

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
