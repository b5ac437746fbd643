"""State estimator node: ``ros2 run maglev_ros estimator``.

Runs the ROS-free :class:`~maglev_ros.estimation.Estimator` (``filter``: kf,
ekf or ukf; every :class:`~maglev_ros.estimation.EstimatorConfig` setting is a
parameter) on the samples of the simulator or the board driver, through
:class:`~maglev_ros.loop.estimate_stage.EstimateStage`: a sample is its
``maglev/currents`` and every sensor's ``maglev/sensor_<k>/field``, in any
order; the filter steps once per sample, in stamp order, and
``maglev/state/estimate`` (nav_msgs/Odometry with covariance; yaw and yaw
rate carry :data:`~maglev_ros.nodes.state_messages.UNOBSERVED_VARIANCE`) is
published with that sample's stamp. ``publish_rate`` (Hz, 0: every sample)
publishes only the samples whose stamp is a multiple of ``1 / publish_rate``
(a real-time controller at a lower rate); the filter still steps every sample.

``/diagnostics``: the NIS over the last ``nis_window`` samples against its
99 % band (WARN outside), readings rejected and missing per sensor, frozen
sensors (WARN), restarts and estimates published.
"""

from __future__ import annotations

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.cdr import CURRENT_VALUES, FIELD_VALUES
from maglev_ros.cdr.reader import RawFieldReader
from maglev_ros.estimation import EstimatorConfig, EstimatorConfigError, make_estimator
from maglev_ros.loop.estimate_stage import EstimateStage
from maglev_ros.nodes.messages import diagnostic_array
from maglev_ros.nodes.params import (
    PARAMS,
    NodeParameterError,
    Param,
    ParameterTable,
    config_params,
    integer,
    number,
)
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.nodes.state_messages import EstimateEncoder
from maglev_ros.topics import CURRENTS_TOPIC, DIAGNOSTICS_TOPIC, ESTIMATE_TOPIC, field_topic

__all__ = ['PARAMETERS', 'EstimatorNode', 'EstimatorNodeConfig', 'EstimatorParameterError']
__all__ += ['build_config', 'main']

NODE_NAME = 'maglev_estimator'


class EstimatorParameterError(NodeParameterError):
    """An estimator parameter has an invalid value."""


@dataclass(frozen=True)
class EstimatorNodeConfig:
    """Validated estimator-node parameters (their meanings: :data:`PARAMETERS`).

    Attributes
    ----------
    params : str
    estimator : EstimatorConfig
    diagnostics_period : float
    sample_wait, publish_every : int
    """

    params: str
    estimator: EstimatorConfig
    diagnostics_period: float
    sample_wait: int = 10
    publish_every: int = 1


PARAMETERS = ParameterTable(
    NODE_NAME,
    EstimatorParameterError,
    {
        'params': PARAMS,
        **config_params(EstimatorConfig),
        'diagnostics_period': Param(
            1.0, 's of the node clock between diagnostics', check=number(0, above=True)
        ),
        'sample_wait': Param(
            10,
            'samples of later stamps a sample waits for a silent sensor before it is missing',
            check=integer(0),
        ),
        'publish_rate': Param(
            0.0,
            'estimates published per second, Hz (0: every sample; else the samples whose '
            'stamp is a multiple of 1 / publish_rate: a real-time controller at a lower rate)',
            check=number(0),
        ),
    },
    removed={
        'intra_process': 'the composed loop runs the hot path as direct calls '
        '(ros2 run maglev_ros loop; closed_loop.launch.xml composes it by default)',
        'stream_thread': 'each message is one callback on the events executor',
    },
)


def build_config(values: dict) -> EstimatorNodeConfig:
    """Validate raw parameter values (a missing name takes its default).

    Parameters
    ----------
    values : dict
        Parameter name to raw value.

    Raises
    ------
    EstimatorParameterError
        Naming the first invalid parameter and its value.
    """
    v = PARAMETERS.validate(values)
    params, period, wait, rate = (
        v.pop(k) for k in ('params', 'diagnostics_period', 'sample_wait', 'publish_rate')
    )
    try:
        config = EstimatorConfig.from_mapping(v)
    except EstimatorConfigError as err:
        raise EstimatorParameterError(str(err)) from err
    every = 1
    if rate > 0:
        every = round(config.sample_rate / rate)
        if every < 1 or abs(every * rate - config.sample_rate) > 1e-9 * config.sample_rate:
            raise EstimatorParameterError(
                f'publish_rate must divide sample_rate {config.sample_rate:g} Hz into whole '
                f'samples (e.g. {config.sample_rate / 5:g}), got {rate:g}'
            )
    return EstimatorNodeConfig(params, config, period, wait, every)


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
        self.config = cfg = build_config(PARAMETERS.declare(self))
        from maglev_ros.physics import make_model

        try:
            model = make_model(cfg.params)
        except (ValueError, OSError) as err:
            raise EstimatorParameterError(f'params {cfg.params!r}: {err}') from err
        self.estimator = make_estimator(model, cfg.estimator)
        self.core = EstimateStage(self.estimator, cfg.sample_wait, cfg.publish_every)
        self.n_sensors = n = self.core.n_sensors
        self._encoder = EstimateEncoder()
        self._encoder.encode(0, self.estimator.x_eq, self.estimator.state_covariance)  # compiled
        self._pub = self.create_publisher(Odometry, ESTIMATE_TOPIC, SENSOR_QOS)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        # raw bytes, read by RawFieldReader: rclpy's message objects cost ~3x the take
        self._readers = [RawFieldReader('sensor_msgs/msg/MagneticField', FIELD_VALUES)] * n
        self._readers.append(
            RawFieldReader('sensor_msgs/msg/JointState', CURRENT_VALUES[: self.estimator.n_inputs])
        )
        for k in range(n):
            self.create_subscription(
                MagneticField,
                field_topic(k),
                lambda raw, k=k: self._on_field(k, raw),
                SENSOR_QOS,
                raw=True,
            )
        self.create_subscription(
            JointState, CURRENTS_TOPIC, self._on_currents, SENSOR_QOS, raw=True
        )
        self.create_timer(cfg.diagnostics_period, self.publish_diagnostics)
        e = cfg.estimator
        self.get_logger().info(
            f'{e.filter} on {cfg.params}, {n} sensors, {e.sample_rate:g} Hz, '
            f'sensor delay {e.sensor_delay}'
            f'{f", each sample the mean of {e.average} readings" if e.average > 1 else ""}'
        )

    @property
    def published(self) -> int:
        """Estimates published."""
        return self.core.published

    @property
    def lost_samples(self) -> int:
        """Samples released without their currents (not estimated)."""
        return self.core.lost_samples

    @property
    def last_stamp(self) -> int | None:
        """Stamp of the last sample estimated, ns."""
        return self.core.last_stamp

    def _on_field(self, k: int, raw: bytes) -> None:
        self._on_part(k, raw)

    def _on_currents(self, raw: bytes) -> None:
        self._on_part(self.n_sensors, raw)

    def _on_part(self, part: int, raw: bytes) -> None:
        read = self._readers[part].read(raw)
        if read is None:
            self.get_logger().error(
                f'{CURRENTS_TOPIC if part == self.n_sensors else field_topic(part)}: message '
                'not read: expected a sensor_msgs message of the contract (little-endian CDR)',
                throttle_duration_sec=1.0,
            )
            return
        estimates, errors = self.core.part(part, *read)
        for e in estimates:
            self._pub.publish(self._encoder.encode(e.stamp_ns, e.x, e.covariance))
        for text in errors:
            self.get_logger().error(text, throttle_duration_sec=1.0)

    def publish_diagnostics(self) -> None:
        """Publish the NIS window, rejected/missing readings and frozen sensors."""
        if not self.context.ok():
            return
        level, message, values = self.core.diagnostic(CURRENTS_TOPIC)
        now_ns = self.get_clock().now().nanoseconds
        self._diag_pub.publish(
            diagnostic_array(now_ns, f'{NODE_NAME}: state estimate', level, message, values)
        )


def main(args: list[str] | None = None) -> int:
    """Run the estimator until SIGINT or SIGTERM; exit status 0, or 2 for bad parameters.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).
    """
    return run_nodes([EstimatorNode], args, NODE_NAME, (EstimatorParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
