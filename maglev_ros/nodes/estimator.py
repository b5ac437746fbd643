"""State estimator node: ``ros2 run maglev_ros estimator``.

Runs the ROS-free :class:`~maglev_ros.estimation.Estimator` (``filter``: kf,
ekf or ukf; :class:`~maglev_ros.estimation.EstimatorConfig` for the other
parameters) on the samples of the simulator or the board driver.

Sample completeness: a sample (one stamp) is its ``maglev/currents`` and
the field ``maglev/sensor_<k>/field`` of every sensor of the parameter set.
The messages of one sample may be handled in any order (distinct topics);
a :class:`~maglev_ros.loop.sample_assembly.SampleAssembler` collects them
and the estimator steps once per sample, in stamp order, once it is complete
-- or once a sensor is known lost: that sensor's field of a later stamp
arrived, a later sample is complete, or samples more than ``sample_wait``
later arrived (a silent sensor). Only then is the sensor missing (NaN,
counted), never because of callback order, so a lockstep graph estimates
exactly as the ROS-free :class:`~maglev_ros.control.ClosedLoop`. A sample
whose currents never came is not estimated (counted as ``lost samples``).
Each step publishes ``maglev/state/estimate``
(nav_msgs/Odometry, frames and angle convention of ``maglev/state/true``,
pose and twist covariance; yaw and yaw rate are unobservable and carry
:data:`~maglev_ros.nodes.state_messages.UNOBSERVED_VARIANCE`) stamped with
that sample's stamp: exactly one estimate per sample, in the order the
ROS-free :class:`~maglev_ros.control.ClosedLoop` steps it.

Every ``diagnostics_period`` s of the node's clock it publishes on
``/diagnostics``: the NIS over the last ``nis_window`` samples against its
99 % band (WARN outside), readings rejected by the gate and missing per
sensor, frozen sensors (WARN), samples estimated, restarts of the filter
(``lost_samples`` without an accepted reading) and estimates published.

``publish_rate`` (Hz, default 0: every sample) publishes only the estimates
of the samples whose stamp is a multiple of ``1 / publish_rate``: a
controller in real time at a lower rate (``trigger: estimate``) gets the
estimate of the last sample of each 1 ms burst of the simulator at 1000 Hz,
and the graph's CPU goes with the control rate, not the sample rate. The
filter still steps every sample.

The fields and currents are taken in a thread of their own
(``stream_thread``, :mod:`~maglev_ros.nodes.sample_streams`): every message
waiting at a wake-up, and a burst's complete samples estimated in one call
(:meth:`~maglev_ros.estimation.Estimator.step_many`); anything unusual goes
through the assembler a message at a time, with the same numbers.
``intra_process`` (composed after the simulator) takes the simulator's
batches directly and offers the estimates to a controller of the same
process (:mod:`~maglev_ros.nodes.intra_process`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.cdr import CURRENT_VALUES, FIELD_VALUES
from maglev_ros.cdr.reader import RawFieldReader
from maglev_ros.estimation import FILTERS, EstimatorConfig, EstimatorConfigError, make_estimator
from maglev_ros.loop.sample_assembly import ReleasedSample, SampleAssembler
from maglev_ros.nodes import intra_process
from maglev_ros.nodes.messages import diagnostic_array
from maglev_ros.nodes.params import NodeParameterError, Param, ParameterTable, choice, number
from maglev_ros.nodes.params import integer as integer_rule
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.nodes.sample_streams import Stream, open_streams
from maglev_ros.nodes.state_messages import EstimateEncoder
from maglev_ros.topics import CURRENTS_TOPIC, DIAGNOSTICS_TOPIC, ESTIMATE_TOPIC, field_topic

__all__ = [
    'PARAMETERS',
    'EstimatorNode',
    'EstimatorNodeConfig',
    'EstimatorParameterError',
    'build_config',
    'main',
]

NODE_NAME = 'maglev_estimator'
_DEFAULT = EstimatorConfig()


class EstimatorParameterError(NodeParameterError):
    """An estimator parameter has an invalid value."""


@dataclass(frozen=True)
class EstimatorNodeConfig:
    """Validated estimator-node parameters.

    Attributes
    ----------
    params : str
        Parameter set the estimator believes (maggy_v2, maggy_v4 or a YAML path).
    estimator : EstimatorConfig
        The filter's settings.
    diagnostics_period : float
        s of the node's clock between diagnostics.
    sample_wait : int
        Samples a sample waits for the field of a silent sensor.
    publish_every : int
        Samples per published estimate (1: every sample; ``publish_rate``).
    stream_thread : bool
        Take the sample streams in a thread of their own (:mod:`.sample_streams`).
    intra_process : bool
        Take the samples from a simulator node of this process (:mod:`.intra_process`).
    """

    params: str
    estimator: EstimatorConfig
    diagnostics_period: float
    sample_wait: int = 10
    publish_every: int = 1
    stream_thread: bool = True
    intra_process: bool = False


def _parameter_set(name: str, value: str) -> str:
    if not value:
        raise EstimatorParameterError(f'{name} must name a parameter set, got an empty string')
    return value


PARAMETERS = ParameterTable(
    NODE_NAME,
    EstimatorParameterError,
    {
        'params': Param(
            'maggy_v2', 'parameter set: maggy_v2, maggy_v4 or a YAML path', check=_parameter_set
        ),
        'filter': Param(
            _DEFAULT.filter, 'kf (linear, default), ekf or ukf', check=choice(*FILTERS)
        ),
        'sample_rate': Param(
            _DEFAULT.sample_rate, 'samples per second, Hz', check=number(0, above=True)
        ),
        'sensor_delay': Param(
            _DEFAULT.sensor_delay,
            'samples of reading delay (the board: 1)',
            check=integer_rule(0, 1),
        ),
        'sensor_noise': Param(
            _DEFAULT.sensor_noise, 'Hall noise, T rms per axis', check=number(0, above=True)
        ),
        'quantization': Param(
            _DEFAULT.quantization, 'Hall resolution, T per LSB', check=number(0)
        ),
        'current_noise': Param(
            _DEFAULT.current_noise, 'current held over a sample, A rms', check=number(0)
        ),
        'acceleration_noise': Param(
            _DEFAULT.acceleration_noise, 'unmodelled force per mass, m/s^2 rms', check=number(0)
        ),
        'angular_acceleration_noise': Param(
            _DEFAULT.angular_acceleration_noise,
            'unmodelled torque per inertia, rad/s^2 rms',
            check=number(0),
        ),
        'bias_states': Param(_DEFAULT.bias_states, 'estimate a field offset per sensor axis'),
        'bias_walk': Param(
            _DEFAULT.bias_walk, 'random walk of the bias states, T rms per sample', check=number(0)
        ),
        'initial_bias': Param(
            _DEFAULT.initial_bias, 'initial std of the bias states, T', check=number(0, above=True)
        ),
        'magnet_strength': Param(
            _DEFAULT.magnet_strength,
            "estimate the magnet's strength as one state (kf only)",
        ),
        'initial_strength': Param(
            _DEFAULT.initial_strength,
            'initial std of the strength state, relative',
            check=number(0, above=True),
        ),
        'strength_walk': Param(
            _DEFAULT.strength_walk,
            'random walk of the strength state, relative rms per sample',
            check=number(0),
        ),
        'lost_samples': Param(
            _DEFAULT.lost_samples,
            'samples without an accepted reading before the filter restarts from its prior',
            check=integer_rule(1),
        ),
        'gate_probability': Param(
            _DEFAULT.gate_probability,
            'per-sensor chi-square gate probability',
            check=number(0.5, above=True, high=1.0),
        ),
        'freeze_samples': Param(
            _DEFAULT.freeze_samples,
            'identical readings in a row that mark a sensor frozen',
            check=integer_rule(2),
        ),
        'nis_window': Param(
            _DEFAULT.nis_window, 'samples of the diagnostics NIS window', check=integer_rule(2)
        ),
        'initial_position': Param(
            _DEFAULT.initial_position, 'initial position std, m', check=number(0, above=True)
        ),
        'initial_angle': Param(
            _DEFAULT.initial_angle, 'initial angle std, rad', check=number(0, above=True)
        ),
        'initial_velocity': Param(
            _DEFAULT.initial_velocity, 'initial velocity std, m/s', check=number(0, above=True)
        ),
        'initial_rate': Param(
            _DEFAULT.initial_rate, 'initial body-rate std, rad/s', check=number(0, above=True)
        ),
        'diagnostics_period': Param(
            1.0, 's of the node clock between diagnostics', check=number(0, above=True)
        ),
        'sample_wait': Param(
            10,
            'samples of later stamps a sample waits for a silent sensor before it is missing',
            check=integer_rule(0),
        ),
        'publish_rate': Param(
            0.0,
            'estimates published per second, Hz (0: every sample; else sample_rate / '
            'publish_rate samples apart, the samples whose stamp is a multiple of that '
            'period: a real-time controller at a lower rate)',
            check=number(0),
        ),
        'stream_thread': Param(
            True,
            'take the fields and currents in a thread of their own, a burst per wake-up '
            '(false: one executor callback per message)',
        ),
        'intra_process': Param(
            False,
            'composed with the simulator node (created before this one, same process): '
            'take its samples directly, not through the middleware (as rclcpp intra-process '
            'communication; the same numbers); no simulator there: subscribe as usual',
        ),
    },
)


_PARAMETERS = PARAMETERS  # the name test_launch uses


def build_config(values: dict) -> EstimatorNodeConfig:
    """Validate raw parameter values.

    Parameters
    ----------
    values : dict
        Parameter name to value (a missing name takes its default).

    Returns
    -------
    EstimatorNodeConfig

    Raises
    ------
    EstimatorParameterError
        Naming the first invalid parameter and its value.
    """
    v = PARAMETERS.validate(values)
    params = v.pop('params')
    period = v.pop('diagnostics_period')
    wait = v.pop('sample_wait')
    rate = v.pop('publish_rate')
    stream_thread = v.pop('stream_thread')
    intra_process = v.pop('intra_process')
    try:
        config = EstimatorConfig.from_mapping(v)
    except EstimatorConfigError as err:
        raise EstimatorParameterError(str(err)) from None
    every = 1
    if rate > 0:
        every = round(config.sample_rate / rate)
        if every < 1 or abs(every * rate - config.sample_rate) > 1e-9 * config.sample_rate:
            raise EstimatorParameterError(
                f'publish_rate must divide sample_rate {config.sample_rate:g} Hz into whole '
                f'samples (e.g. {config.sample_rate / 5:g}), got {rate:g}'
            )
    return EstimatorNodeConfig(params, config, period, wait, every, stream_thread, intra_process)


class EstimatorNode(Node):
    """The state estimator (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    EstimatorParameterError
        If a parameter is invalid (or the parameter set cannot be read).
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.streams = self.source = self.estimates = None
        self.config = cfg = build_config(PARAMETERS.declare(self))
        from maglev_ros.physics import make_model

        try:
            model = make_model(cfg.params)
        except (ValueError, OSError) as err:
            raise EstimatorParameterError(f'params {cfg.params!r}: {err}') from None
        self.estimator = make_estimator(model, cfg.estimator)
        # load the compiled kernels now, not on the first sample (up to 1 s: a real-time
        # loop would go stale), then start from the prior
        self._encoder = EstimateEncoder()
        x = self.estimator.step(self.estimator.y_eq, self.estimator.u_eq)
        self._encoder.encode(0, x, self.estimator._out_p)
        self.estimator.step_many(self.estimator.y_eq[None], self.estimator.u_eq[None])
        self.estimator.reset()
        self.n_sensors = self.estimator.n_sensors
        self._period_ns = 1e9 / cfg.estimator.sample_rate
        # parts 0 .. k-1: the sensors' fields; part k: the currents
        self._samples = SampleAssembler(
            self.n_sensors + 1, round(cfg.sample_wait * self._period_ns)
        )
        self.lost_samples = 0  # released without their currents: not estimated
        self.published = 0
        self.last_stamp: int | None = None
        self._pub = self.create_publisher(Odometry, ESTIMATE_TOPIC, SENSOR_QOS)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        # raw bytes, read by RawFieldReader: rclpy's message objects cost ~3x the take
        self._field_readers = [
            RawFieldReader('sensor_msgs/msg/MagneticField', FIELD_VALUES)
            for _ in range(self.n_sensors)
        ]
        self._currents_reader = RawFieldReader(
            'sensor_msgs/msg/JointState', CURRENT_VALUES[: self.estimator.n_inputs]
        )
        self.source = None  # intra_process: the simulator's samples, not its messages
        self.estimates = None  # intra_process: the estimates, for a controller of this process
        if cfg.intra_process:
            self.source = self._connect_source()
            self.estimates = intra_process.Channel()
            self.estimates.on_error = self._on_listener_error
            self._estimates_topic = self.resolve_topic_name(ESTIMATE_TOPIC)
            intra_process.register(self.context, self._estimates_topic, self.estimates)
        if self.source is None:
            self._subscribe_streams(cfg)
        self.create_timer(cfg.diagnostics_period, self.publish_diagnostics)
        self.get_logger().info(
            f'{cfg.estimator.filter} on {cfg.params}, {self.n_sensors} sensors, '
            f'{cfg.estimator.sample_rate:g} Hz, sensor delay {cfg.estimator.sensor_delay}'
            f'{", samples from the simulator in this process" if self.source else ""}'
        )

    def _connect_source(self):
        """Connect to the simulator of this process (intra_process); None if there is none."""
        source = intra_process.find(self.context, self.resolve_topic_name(CURRENTS_TOPIC))
        wanted = tuple(range(self.n_sensors))
        if (
            not isinstance(source, intra_process.Channel)
            or source.sensors[: self.n_sensors] != wanted
        ):
            self.get_logger().warning(
                'intra_process: no simulator publishing sensors '
                f'{list(wanted)} in this process (create it first): subscribing instead'
            )
            return None
        source.connect(self._on_batch, NODE_NAME)
        return source

    def _on_listener_error(self, name: str, err: Exception) -> None:
        self.get_logger().error(
            f'{name}: estimate not taken in this process: {err}', throttle_duration_sec=1.0
        )

    def _on_batch(self, batch) -> None:
        """Estimate a batch of the simulator's samples (intra_process; its thread)."""
        if len(batch):
            self._estimate_many(
                [int(t) for t in batch.stamps_ns],
                batch.readings[:, : 3 * self.n_sensors],
                batch.currents[:, : self.estimator.n_inputs],
            )

    def _estimate_many(self, stamps: list[int], ys: np.ndarray, currents: np.ndarray) -> None:
        """Step the estimator with complete samples in order; publish their estimates."""
        try:
            x, p = self.estimator.step_many(ys, currents)
        except ValueError as err:  # not finite: say so, keep running
            self.get_logger().error(
                f'samples {stamps[0]}..{stamps[-1]} ns not estimated: {err}',
                throttle_duration_sec=1.0,
            )
            return
        self.last_stamp = stamps[-1]
        for i, stamp in enumerate(stamps):
            self._publish_estimate(stamp, x[i], p[i])

    def _publish_estimate(self, stamp: int, x: np.ndarray, p: np.ndarray) -> None:
        """Publish the estimate of the sample at ``stamp`` if ``publish_rate`` wants it."""
        every = self.config.publish_every
        if every > 1 and round(stamp / self._period_ns) % every:
            return  # not a publishing sample (publish_rate)
        if self.estimates is None or self._pub.get_subscription_count():
            # composed (intra_process), an estimate nobody subscribes to is neither
            # serialised nor published (volatile: no late subscriber could get it)
            self._pub.publish(self._encoder.encode(stamp, x, p))
        self.published += 1
        if self.estimates is not None and self.estimates.listeners:
            self.estimates.deliver(stamp, x)

    def _on_burst(self, taken: list[list[bytes]]) -> None:
        """Estimate a wake-up's messages: whole samples at once, else one message at a time.

        The usual burst: the first n messages of every part (the fields, the
        currents; n the fewest any part has) carry the same stamps in the same
        order, newer than the last sample, and no sample is pending. Those n
        samples are read and estimated in one call
        (:meth:`~maglev_ros.estimation.Estimator.step_many`); the rest wait for
        the next wake-up (a thread behind takes more of one topic than of
        another). Anything else (a sample pending, stamps that differ, an
        unreadable message, a part with no message while another has more than
        ``sample_wait``: a silent sensor) goes through the assembler one
        message at a time, oldest stamp first, until no sample is pending;
        then whole samples again (unless they did not line up in this
        wake-up).
        """
        waiting = self._waiting
        for part, raws in enumerate(taken):
            waiting[part].extend(raws)
        aligned = True  # False once whole samples did not line up: the rest one at a time
        heads: list[int | None] = [None] * len(waiting)  # stamp of each part's first, once read
        while any(waiting):
            if self._samples.pending == 0 and aligned:
                lengths = [len(w) for w in waiting]
                n = min(lengths)
                if n == 0 and max(lengths) <= self.config.sample_wait:
                    return  # part of a burst: the rest comes with the next wake-up
                if n:
                    aligned = self._estimate_aligned(n)
                    if aligned:  # n of each consumed
                        heads = [None] * len(waiting)
                    continue
            # the oldest message first (by stamp; for one stamp, in part order), until no
            # sample is pending: a topic that came late within the wake-up (more than
            # sample_wait behind the others) is merged in, not handled sample_wait late
            for p, w in enumerate(waiting):
                if w and heads[p] is None:
                    heads[p] = self._head_stamp(p)
            part = min((heads[p], p) for p, w in enumerate(waiting) if w)[1]
            heads[part] = None
            self._handlers[part](waiting[part].pop(0))

    def _head_stamp(self, part: int) -> int:
        """Return the stamp of the oldest waiting message of ``part``, ns (-1: unreadable)."""
        read = self._readers[part].read(self._waiting[part][0])
        return -1 if read is None else read[0]

    def _estimate_aligned(self, n: int) -> bool:
        """Estimate the first ``n`` messages of every part as ``n`` whole samples.

        Returns
        -------
        bool
            False (nothing consumed) when they are not ``n`` whole samples in
            order, newer than the last one released.
        """
        waiting = self._waiting
        reads = [
            [reader.read(raw) for raw in w[:n]]
            for reader, w in zip(self._readers, waiting, strict=True)
        ]
        stamps = [r[0] if r is not None else None for r in reads[-1]]
        if not (
            None not in stamps
            and stamps[0] > self._samples.released
            and all(stamps[i] < stamps[i + 1] for i in range(n - 1))
            and all([r[0] if r else None for r in rs] == stamps for rs in reads[:-1])
        ):
            return False
        ys = np.array([sum((rs[i][1] for rs in reads[:-1]), ()) for i in range(n)])
        currents = np.array([r[1] for r in reads[-1]])
        self._samples.handled(stamps[-1])
        for w in waiting:
            del w[:n]
        self._estimate_many(stamps, ys, currents)
        return True

    def _subscribe_streams(self, cfg: EstimatorNodeConfig) -> None:
        # the 5 kHz streams in a thread of their own, a burst per wake-up (sample_streams)
        streams = [
            Stream(MagneticField, field_topic(k), lambda raw, k=k: self._on_field(k, raw))
            for k in range(self.n_sensors)
        ]
        streams.append(Stream(JointState, CURRENTS_TOPIC, self._on_currents))
        self._handlers = [stream.callback for stream in streams]
        self._readers = [*self._field_readers, self._currents_reader]
        self._waiting: list[list[bytes]] = [[] for _ in streams]  # burst: per part
        self.streams = open_streams(
            self, streams, SENSOR_QOS, own_thread=cfg.stream_thread, burst=self._on_burst
        )

    def destroy_node(self) -> None:
        """Stop the sample streams' thread, then destroy the node."""
        if self.streams is not None:
            self.streams.close()
        if self.source is not None:
            self.source.disconnect(self._on_batch)
        if self.estimates is not None:
            intra_process.unregister(self.context, self._estimates_topic, self.estimates)
        super().destroy_node()

    def _unreadable(self, topic: str, what: str) -> None:
        self.get_logger().error(
            f'{topic}: message not read: expected {what} (little-endian CDR)',
            throttle_duration_sec=1.0,
        )

    def _on_field(self, k: int, raw: bytes) -> None:
        read = self._field_readers[k].read(raw)
        if read is None:
            self._unreadable(field_topic(k), 'a sensor_msgs/MagneticField')
            return
        for sample in self._samples.add(k, *read):
            self._estimate(sample)

    def _on_currents(self, raw: bytes) -> None:
        read = self._currents_reader.read(raw)
        if read is None:
            n = self.estimator.n_inputs
            self._unreadable(CURRENTS_TOPIC, f'a sensor_msgs/JointState with {n} efforts')
            return
        for sample in self._samples.add(self.n_sensors, *read):
            self._estimate(sample)

    def _estimate(self, sample: ReleasedSample) -> None:
        """Step the estimator with one released sample and publish its estimate."""
        stamp, parts = sample.stamp, sample.parts
        if parts[-1] is None:
            self.lost_samples += 1  # no currents: the sample cannot be estimated
            return
        fields = parts[:-1]
        if None in fields:
            y = np.full(3 * self.n_sensors, np.nan)
            for k, field in enumerate(fields):
                if field is not None:
                    y[3 * k : 3 * k + 3] = field
        else:
            y = np.array(sum(fields, ()))
        self._step(stamp, y, np.array(parts[-1]))

    def _step(self, stamp: int, y: np.ndarray, currents: np.ndarray) -> None:
        """Step the estimator with one sample's readings and currents; publish its estimate."""
        try:
            x = self.estimator.step(y, currents)
        except ValueError as err:  # a malformed message: say so, keep running
            self.get_logger().error(
                f'sample {stamp} ns not estimated: {err}', throttle_duration_sec=1.0
            )
            return
        self.last_stamp = stamp
        self._publish_estimate(stamp, x, self.estimator._out_p)

    def publish_diagnostics(self) -> None:
        """Publish the NIS window, rejected/missing readings and frozen sensors."""
        if not self.context.ok():
            return
        s = self.estimator.status()
        if s.samples == 0:
            level, message = DiagnosticStatus.OK, f'waiting for samples on {CURRENTS_TOPIC}'
        elif s.frozen:
            level = DiagnosticStatus.WARN
            message = f'frozen: {", ".join(s.frozen_names())} (readings ignored until they change)'
        elif not s.nis_ok:
            level = DiagnosticStatus.WARN
            message = (
                f'NIS {s.nis_window:.1f} outside its 99 % band '
                f'[{s.nis_band[0]:.1f}, {s.nis_band[1]:.1f}]: check sensor_noise and the model'
            )
        else:
            level, message = DiagnosticStatus.OK, f'estimating ({self.config.estimator.filter})'
        values = {
            'samples': s.samples,
            'NIS window': f'{s.nis_window:.6g}',
            'NIS dof': s.nis_dof,
            'NIS 99 % band': f'{s.nis_band[0]:.6g} {s.nis_band[1]:.6g}',
            'rejected per sensor': ' '.join(str(v) for v in s.rejected),
            'missing per sensor': ' '.join(str(v) for v in s.missing),
            'frozen sensors': ' '.join(s.frozen_names()),
            'freeze events per sensor': ' '.join(str(v) for v in s.freeze_events),
            'lost samples (no currents)': self.lost_samples,
            'restarts': s.restarts,
            'estimates published': self.published,
            'late messages': self._samples.late,
        }
        now_ns = self.get_clock().now().nanoseconds
        self._diag_pub.publish(
            diagnostic_array(now_ns, f'{NODE_NAME}: state estimate', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Run the estimator until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return run_nodes([EstimatorNode], args, NODE_NAME, (EstimatorParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
