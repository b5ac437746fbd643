"""Simulator node: ``ros2 run maglev_ros simulator``.

The nonlinear Maggy model (:class:`~maglev_ros.physics.Simulator`) as a plant
on the topics of ``docs/topics.md``, as the board driver: per sample (stamped
with simulated time) each sensor's field, the true state and the currents
(last: they complete a sample); ``/clock``; markers; ``/diagnostics``. It takes
JointState commands (names x+ x- y+ y- or none, effort in A, stamp = the sample
answered) and the reset (Trigger) and pause (SetBool) services. A shell around
a ROS-free :class:`~maglev_ros.physics.session.SimulationSession` (it states
the timing contract; a crash stops it until a reset):

``realtime``
    A steady-clock timer (every ``pace_period``) publishes the samples due; a
    command holds from the next burst. With ``wait_for_controller`` the run
    starts once a command came and the graph is ready (:mod:`.start_gate`).
``lockstep``
    Each command steps and publishes the next sample (early ones queue). A
    timer starts the run once the graph is ready, and holds the last command
    after ``command_timeout``.
"""

from __future__ import annotations

import time
from functools import partial

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.clock import Clock as SteadyClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, MagneticField
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from maglev_ros.nodes import contract, params
from maglev_ros.nodes.markers import base_markers, magnet_marker, marker_array
from maglev_ros.nodes.messages import command_currents, stamp_ns
from maglev_ros.nodes.params import NodeParameterError, Param, ParameterTable, integer, number
from maglev_ros.nodes.params import choice as one_of
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.nodes.start_gate import StartGate
from maglev_ros.physics import FIELD_MODELS, KINEMATICS, TORQUE_MODES, Simulator
from maglev_ros.physics import simulator_config as core
from maglev_ros.physics.sample_encoder import SampleEncoder
from maglev_ros.physics.session import MODES, SampleBatch, SimulationSession
from maglev_ros.physics.session_health import crash_line, session_health
from maglev_ros.physics.simulation import MAGNET_MODES
from maglev_ros.physics.simulator_config import SimulatorConfig
from maglev_ros.topics import SIMULATOR_PAUSE_SERVICE, SIMULATOR_RESET_SERVICE

__all__ = ['MODES', 'PARAMETERS', 'SimulatorConfig', 'SimulatorNode', 'SimulatorParameterError',
           'build_config', 'main', 'make_simulator']  # fmt: skip

NODE_NAME = 'maglev_simulator'
STEADY_TIME = ClockType.STEADY_TIME
#: Fast DDS sends from its own thread (5 kHz with a recorder: real-time factor 0.9 -> 1.0)
ASYNC = {'RMW_FASTRTPS_PUBLICATION_MODE': 'ASYNCHRONOUS'}


class SimulatorParameterError(NodeParameterError):
    """A simulator parameter has an invalid value."""


_CHECK = {'error': SimulatorParameterError}  # the config's checks raise the node's error

# fmt: off
PARAMETERS = ParameterTable(NODE_NAME, SimulatorParameterError, {
    'params': Param('maggy_v2', 'parameter set: maggy_v2, maggy_v4 or a YAML path',
                    check=partial(core.check_parameter_set, **_CHECK)),
    'field_model': Param('fast', 'field model: fast, accurate or filament',
                         check=one_of(*FIELD_MODELS)),
    'torque': Param('true', 'torque model: true or published', check=one_of(*TORQUE_MODES)),
    'kinematics': Param('rigid', 'kinematics: rigid or published', check=one_of(*KINEMATICS)),
    'sample_rate': Param(5000.0, 'samples per second, Hz (the board: 5000)',
                         check=number(0, above=True)),
    'substeps': Param(1, 'RK4 steps per sample', check=integer(1)),
    'magnet': Param('free', 'levitating magnet: free, fixed (held at the initial state) or absent',
                    check=one_of(*MAGNET_MODES)),
    'hold': Param(0.0, 'free magnet: s held at the initial state after each start, then released '
                  '(a hand holding it while the loop comes up)', check=number(0)),
    'initial_state': Param([], '12 numbers x y z alpha beta gamma vx vy vz wx wy wz (m, rad, '
                           'm/s, rad/s); empty: resting at the first equilibrium',
                           kind='double_array', check=partial(core.check_initial_state, **_CHECK)),
    'coil_dynamics': Param(True, 'coil L/R electrics, voltage R i_cmd clipped at the supply'),
    'sensor_noise': Param(0.0, 'white sensor noise per axis, T rms', check=number(0)),
    'sensor_quantization': Param(0.0, 'sensor resolution, T per LSB (0: none)', check=number(0)),
    'sensor_delay': Param(1, 'sensor delay in samples (the board has 1)', check=integer(0)),
    'seed': Param(0, 'seed of the sensor noise', check=integer(0)),
    'average': Param(1, 'realtime: steps per published sample, each the mean of their readings '
                     'and currents (5 at 5 kHz: 1 kHz); 1: every step', check=integer(1)),
    'mode': Param('realtime', 'timing: realtime (wall clock) or lockstep (one command per sample)',
                  check=one_of(*MODES)),
    'command_timeout': Param(1.0, 'lockstep: s to wait for a command before holding the last one',
                             check=number(0, above=True)),
    'pace_period': Param(0.001, 'realtime: s of wall time per burst of samples (0: every sample)',
                         check=number(0)),
    'start_paused': Param(False, f'start paused (resume with {SIMULATOR_PAUSE_SERVICE} false)'),
    'start_subscribers': Param(0, f'subscribers of {contract.CURRENTS_TOPIC} to wait for at start '
                               '(lockstep; real time with wait_for_controller)', check=integer(0)),
    'wait_for_controller': Param(False, f'realtime: start only once a first '
                                 f'{contract.COMMAND_TOPIC} arrived and start_subscribers '
                                 'subscribers exist (a free magnet waits for its controller)'),
    'start_reader': Param('', 'a node (a recorder) that must read the start_reader_topics before '
                          "the start, as start_subscribers; '': none", check=params.node_name()),
    'start_reader_topics': Param([contract.COMMAND_TOPIC], "topics other nodes publish that the "
                                 'start_reader must read', check=params.topic_names()),
    'sensors': Param([], 'indices of the sensors to publish; empty: all', kind='integer_array',
                     check=partial(core.check_sensor_indices, **_CHECK)),
    'publish_state': Param(True, f'publish the true state on {contract.TRUE_STATE_TOPIC}'),
    'publish_clock': Param(True, f'publish the simulated time on {contract.CLOCK_TOPIC}'),
    'marker_rate': Param(10.0, 'RViz markers per second of wall time (0: none)', check=number(0)),
    'diagnostics_period': Param(1.0, f's between {contract.DIAGNOSTICS_TOPIC} messages',
                                check=number(0, above=True)),
})
# fmt: on
_PARAMETERS = PARAMETERS  # the name test_launch uses


def build_config(values: dict) -> SimulatorConfig:
    """Validate raw parameter values into a config; errors name the parameter.

    Parameters
    ----------
    values : dict
        Parameter name to raw value (a missing name takes its default).
    """
    return SimulatorConfig(**PARAMETERS.validate(values))


def make_simulator(cfg: SimulatorConfig) -> Simulator:
    """Build the simulator of a config (errors as :class:`SimulatorParameterError`).

    Parameters
    ----------
    cfg : SimulatorConfig
        The validated parameters.
    """
    try:
        return core.make_simulator(cfg)
    except core.SimulatorConfigError as err:
        raise SimulatorParameterError(str(err)) from err


class SimulatorNode(Node):
    """The simulator (see the module docstring): callbacks feed the session, publish its samples.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``, ``parameter_overrides``).
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.config = cfg = build_config(PARAMETERS.declare(self))
        self.sim = make_simulator(cfg)
        self.session = session = SimulationSession(
            self.sim, cfg.mode, pace_period=cfg.pace_period,
            command_timeout=cfg.command_timeout, paused=cfg.start_paused, average=cfg.average,
        )  # fmt: skip
        self.counters = session.counters
        self.sensors = cfg.sensors or tuple(range(len(self.sim.model.params.sensors)))
        lockstep = cfg.mode == 'lockstep'
        clock = 'none' if not cfg.publish_clock else 'sample' if lockstep else 'burst'
        burst = max(1, session.burst // cfg.average)  # published samples per burst
        self._encoder = SampleEncoder(self.sensors, cfg.publish_state, clock, burst)
        types = {contract.field_topic(k): MagneticField for k in self.sensors}
        types |= {contract.TRUE_STATE_TOPIC: Odometry, contract.CURRENTS_TOPIC: JointState}
        topics = (*self._encoder.topics, *[contract.CLOCK_TOPIC] * (clock == 'burst'))
        pubs = {
            t: self.create_publisher(types.get(t, Clock), t, contract.SENSOR_QOS) for t in topics
        }
        self._sample_pubs = [pubs[t] for t in self._encoder.topics]
        self._current_pub = pubs[contract.CURRENTS_TOPIC]
        self._clock_call = pubs[topics[-1]].handle.publish_raw if clock == 'burst' else None
        self._diag_pub = self.create_publisher(DiagnosticArray, contract.DIAGNOSTICS_TOPIC,
                                               contract.DIAGNOSTICS_QOS)  # fmt: skip
        qos = contract.LOCKSTEP_COMMAND_QOS if lockstep else contract.COMMAND_QOS
        self._command_sub = self.create_subscription(
            JointState, contract.COMMAND_TOPIC, self._on_command, qos
        )
        self.create_service(Trigger, SIMULATOR_RESET_SERVICE, self._on_reset)
        self.create_service(SetBool, SIMULATOR_PAUSE_SERVICE, self._on_pause)
        self.create_timer(cfg.diagnostics_period, self.publish_diagnostics)  # the node's clock
        if cfg.marker_rate > 0:
            self._marker_pub = self.create_publisher(MarkerArray, contract.MARKERS_TOPIC,
                                                     contract.MARKERS_QOS)  # fmt: skip
            self._base_markers = base_markers(self.sim.model.params)
            self.create_timer(1.0 / cfg.marker_rate, self.publish_markers)
        # pacing on the steady clock: under use_sim_time the node's clock is the
        # /clock this node publishes, which does not run before the first samples
        period = min(0.05, cfg.command_timeout / 4) if lockstep else session.burst * session.dt
        self.create_timer(period, self._on_tick, clock=SteadyClock(clock_type=STEADY_TIME))
        self._ready = StartGate(self, self._current_pub, cfg)
        if not lockstep and not cfg.wait_for_controller:
            self._send(session.start(time.monotonic()))
        self.get_logger().info(cfg.summary(self.sim.model.params.name, self.sensors))

    @property
    def currents_subscribers(self) -> int:
        """Subscriptions matched to ``maglev/currents``."""
        return self._current_pub.get_subscription_count()

    @property
    def command_publishers(self) -> int:
        """Publishers matched to the command subscription (discovery is per side: wait on both)."""
        return self._command_sub.get_publisher_count()

    def _on_tick(self) -> None:
        self._send(*self.session.tick(time.monotonic(), self._ready))

    def _on_command(self, msg: JointState) -> None:
        try:
            batch = self.session.command(command_currents(msg), time.monotonic(), stamp_ns(msg))
        except ValueError as err:  # the names; the number or values (counted by the session)
            self.get_logger().warning(f'rejected command: {err}', throttle_duration_sec=1.0)
        else:
            self._send(batch)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response):
        response.message, response.success = self.reset(), True
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response):
        self.set_paused(request.data)
        response.message = 'paused' if self.session.paused else 'running'
        response.success = True
        self.get_logger().info(f'simulation {response.message}')
        return response

    def reset(self) -> str:
        """Restart from the initial state (recovers a crash); return a description."""
        self._send(self.session.reset(time.monotonic()))
        message = f'reset: new run starts at {self.session.run_start_ns * 1e-9:.6f} s'
        self.get_logger().info(message)
        return message

    def set_paused(self, paused: bool) -> None:
        """Pause or resume the integration (lockstep: queued commands step on resume).

        Parameters
        ----------
        paused : bool
            True pauses, False resumes.
        """
        self._send(self.session.set_paused(paused, time.monotonic()))

    def _send(self, batch: SampleBatch | None, note: str = '', warning: bool = False) -> None:
        """Publish a batch (topics nobody reads are skipped); log a note or a crash."""
        if warning:  # a lockstep timeout
            self.get_logger().warning(note, throttle_duration_sec=1.0)
        elif note:
            self.get_logger().info(note)
        if batch is None:
            return
        calls = [p.handle.publish_raw if p.get_subscription_count() else None
                 for p in self._sample_pubs]  # fmt: skip
        self._encoder.publish(batch, calls, self._clock_call)
        if batch.crashed:
            self.get_logger().error(crash_line(self.session))
            self.publish_diagnostics()

    def publish_markers(self) -> None:
        """Publish the base and the magnet (at its latest state) as RViz markers."""
        markers = list(self._base_markers)
        if self.config.magnet != 'absent':
            state = self.session.last_state
            markers.append(magnet_marker(self.sim.model.params, state, self.sim.crashed))
        self._marker_pub.publish(marker_array(markers, max(self.session.last_stamp_ns, 0)))

    def publish_diagnostics(self) -> None:
        """Publish the run state and counters on ``/diagnostics``, stamped by the node's clock."""
        if not self.context.ok():  # a signal is shutting the node down
            return
        self.session.measure_real_time_factor(time.monotonic())
        health = session_health(self.session, self.config.magnet)
        self._diag_pub.publish(
            contract.diagnostic_array(
                self.get_clock().now().nanoseconds, f'{NODE_NAME}: simulation',
                health.level, health.message, health.values, hardware_id='simulator',
            )
        )  # fmt: skip


def main(args: list[str] | None = None) -> int:
    """Run the simulator until SIGINT, SIGTERM or SIGHUP; exit status 0, or 2 on bad parameters.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).
    """
    return run_nodes([SimulatorNode], args, NODE_NAME, (PARAMETERS.error,), PARAMETERS, ASYNC)


if __name__ == '__main__':
    raise SystemExit(main())
