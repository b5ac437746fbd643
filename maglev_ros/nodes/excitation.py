"""Excitation node: ``ros2 run maglev_ros excitation``.

Publishes identification inputs on ``maglev/currents/command``
(sensor_msgs/JointState, names x+ x- y+ y-, effort = currents in A): PRBS,
random binary, multisine or chirp (:mod:`maglev_ros.excitation`), with
amplitude, band (fractions of Nyquist), per-solenoid pattern (``pairs``: +u_x
on x+, -u_x on x-, +u_y on y+, -u_y on y-, the board's antisymmetric pairs;
``x_pair``, ``y_pair``, ``independent``, ``common``), offset and seed.

One period of ``length`` samples is generated at start and repeated
``cycles`` times (0: forever); afterwards zero currents plus ``offset`` are
sent. ``max_commands`` (0: no limit) stops publishing after that many
commands: a lockstep simulation then takes exactly that many steps
(:class:`~maglev_ros.excitation.CommandSequence`). Triggers:

``sample`` (default)
    one command per sample received on ``maglev/currents`` (from the
    simulator or the driver), stamped with that sample's stamp: in lockstep
    this drives the simulation sample by sample, deterministically.
``timer``
    one command per 1 / ``sample_rate`` s of wall time, stamped with the
    node clock's time (no sample is answered).

QoS: RELIABLE, KEEP_LAST 1000 (matches the simulator's lockstep command
subscription and the driver's best-effort one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState

from maglev_ros.excitation import (
    PATTERNS,
    SIGNALS,
    CommandSequence,
    apply_pattern,
    excitation,
    pattern_signals,
)
from maglev_ros.nodes.params import (
    NodeParameterError,
    Param,
    ParameterTable,
    choice,
    integer,
    number,
)
from maglev_ros.nodes.qos import LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.topics import COIL_NAMES, COMMAND_TOPIC, CURRENTS_TOPIC

__all__ = ['PARAMETERS', 'ExcitationConfig', 'ExcitationNode', 'ExcitationParameterError',
           'build_config', 'commands_of', 'main']  # fmt: skip

NODE_NAME = 'maglev_excitation'
TRIGGERS = ('sample', 'timer')


class ExcitationParameterError(NodeParameterError):
    """An excitation parameter has an invalid value."""


@dataclass(frozen=True)
class ExcitationConfig:
    """Validated excitation parameters.

    Attributes
    ----------
    signal : str
        ``prbs``, ``random_binary``, ``multisine`` or ``chirp``.
    amplitude : float
        Peak per signal, A.
    band : tuple of float
        (low, high), fractions of Nyquist.
    pattern : str
        Coil pattern.
    offset : tuple of float
        4 currents added to every command, A.
    seed : int
        Seed.
    length : int
        Samples per period.
    cycles : int
        Periods to send (0: forever).
    trigger : str
        ``sample`` or ``timer``.
    sample_rate : float
        Hz (timer trigger).
    max_commands : int
        Commands to publish before stopping (0: no limit).
    """

    signal: str
    amplitude: float
    band: tuple[float, float]
    pattern: str
    offset: tuple[float, ...]
    seed: int
    length: int
    cycles: int
    trigger: str
    sample_rate: float
    max_commands: int = 0


def _band(name: str, band: tuple[float, ...]) -> tuple[float, ...]:
    if len(band) != 2 or not (0.0 <= band[0] < band[1] <= 1.0):
        raise ExcitationParameterError(
            f'{name} must be [low, high] with 0 <= low < high <= 1, got {list(band)}'
        )
    return band


def _offset(name: str, offset: tuple[float, ...]) -> tuple[float, ...]:
    if len(offset) != 4 or not all(math.isfinite(v) for v in offset):
        raise ExcitationParameterError(f'{name} must be 4 finite currents, got {list(offset)}')
    return offset


PARAMETERS = ParameterTable(
    NODE_NAME,
    ExcitationParameterError,
    {
        'signal': Param('prbs', 'prbs, random_binary, multisine or chirp', check=choice(*SIGNALS)),
        'amplitude': Param(0.5, 'peak of each signal, A', check=number(0)),
        'band': Param([0.0, 1.0], 'pass band (low, high) as fractions of Nyquist', check=_band),
        'pattern': Param(
            'pairs',
            'coil pattern: pairs, x_pair, y_pair, independent or common',
            check=choice(*PATTERNS),
        ),
        'offset': Param(
            [0.0, 0.0, 0.0, 0.0],
            f'currents added to every command, A ({" ".join(COIL_NAMES)})',
            check=_offset,
        ),
        'seed': Param(0, 'seed of the signals', check=integer(0)),
        'length': Param(8191, 'samples per period', check=integer(1)),
        'cycles': Param(0, 'periods to send (0: forever); then offset only', check=integer(0)),
        'trigger': Param(
            'sample',
            f'sample: one command per {CURRENTS_TOPIC} message; timer: wall clock',
            check=choice(*TRIGGERS),
        ),
        'sample_rate': Param(
            5000.0, 'timer trigger: commands per second, Hz', check=number(0, above=True)
        ),
        'max_commands': Param(
            0,
            'commands to publish, then none (0: no limit; lockstep: exact samples)',
            check=integer(0),
        ),
    },
)
_PARAMETERS = PARAMETERS  # the name test_launch and older callers use


def build_config(values: dict) -> ExcitationConfig:
    """Validate raw parameter values.

    Parameters
    ----------
    values : dict
        Parameter name to value (a missing name takes its default).

    Returns
    -------
    ExcitationConfig

    Raises
    ------
    ExcitationParameterError
        Naming the first invalid parameter and its value.
    """
    return ExcitationConfig(**PARAMETERS.validate(values))


def commands_of(cfg: ExcitationConfig) -> np.ndarray:
    """One period of coil commands of a configuration, shape (length, 4), A.

    Parameters
    ----------
    cfg : ExcitationConfig
        The validated parameters.

    Raises
    ------
    ExcitationParameterError
        If the signal cannot be generated with these settings.
    """
    try:
        signals = excitation(
            cfg.signal, cfg.length, pattern_signals(cfg.pattern), cfg.amplitude, cfg.band, cfg.seed
        )
    except ValueError as err:
        raise ExcitationParameterError(f'{cfg.signal}: {err}') from err
    return apply_pattern(signals, cfg.pattern, cfg.offset)


class ExcitationNode(Node):
    """The excitation publisher (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    ExcitationParameterError
        If a parameter is invalid.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.config = cfg = build_config(PARAMETERS.declare(self))
        self.commands = commands_of(cfg)
        self.sequence = CommandSequence(self.commands, cfg.cycles, cfg.offset, cfg.max_commands)
        self._pub = self.create_publisher(JointState, COMMAND_TOPIC, LOCKSTEP_COMMAND_QOS)
        if cfg.trigger == 'sample':
            self.create_subscription(
                JointState, CURRENTS_TOPIC, self._on_sample, SENSOR_QOS, raw=True
            )
        else:
            self.create_timer(1.0 / cfg.sample_rate, self.publish_next)
        self.get_logger().info(
            f'{cfg.signal}, {cfg.amplitude:g} A, band {list(cfg.band)}, pattern {cfg.pattern}, '
            f'{cfg.length} samples x {cfg.cycles or "inf"}, seed {cfg.seed}, '
            f'trigger {cfg.trigger}'
        )

    @property
    def sent(self) -> int:
        """Commands published so far."""
        return self.sequence.sent

    @property
    def finished(self) -> bool:
        """True once all cycles were sent (offset only from then on)."""
        return self.sequence.finished

    @property
    def exhausted(self) -> bool:
        """True once ``max_commands`` commands were published (nothing more is sent)."""
        return self.sequence.exhausted

    @property
    def command_subscribers(self) -> int:
        """Subscriptions matched to this node's ``maglev/currents/command`` publisher.

        Counts every matched subscription in the graph (the simulator's or
        driver's, a recorder's, ...): wait on it for discovery before the
        first command so that it is received.
        """
        return self._pub.get_subscription_count()

    def publish_next(self, stamp_ns: int | None = None) -> None:
        """Publish the next command (nothing once ``max_commands`` are sent).

        Parameters
        ----------
        stamp_ns : int, optional
            Stamp of the sample it answers, ns (default: the node clock's time).
        """
        now = self.get_clock().now().nanoseconds if stamp_ns is None else stamp_ns
        self._publish(self.sequence.message(now))

    def _on_sample(self, raw: bytes) -> None:
        self._publish(self.sequence.answer(raw))  # stamped with the sample it answers

    def _publish(self, message: bytes | None) -> None:
        if message is not None:
            self._pub.publish(message)


def main(args: list[str] | None = None) -> int:
    """Run the excitation until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return run_nodes([ExcitationNode], args, NODE_NAME, (ExcitationParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
