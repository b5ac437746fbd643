"""Excitation node: ``ros2 run maglev_ros excitation``.

Publishes identification inputs on ``maglev/currents/command``
(std_msgs/Float64MultiArray, 4 currents in A, x+ x- y+ y-): PRBS, random
binary, multisine or chirp (:mod:`maglev_ros.excitation`), with amplitude,
band (fractions of Nyquist), per-solenoid pattern (``pairs``: +u_x on x+,
-u_x on x-, +u_y on y+, -u_y on y-, the board's antisymmetric pairs;
``x_pair``, ``y_pair``, ``independent``, ``common``), offset and seed.

One period of ``length`` samples is generated at start and repeated
``cycles`` times (0: forever); afterwards zero currents plus ``offset`` are
sent. ``max_commands`` (0: no limit) stops publishing after that many
commands: a lockstep simulation then takes exactly that many steps. Triggers:

``sample`` (default)
    one command per sample received on ``maglev/currents`` (from the
    simulator or the driver): in lockstep this drives the simulation sample
    by sample, deterministically.
``timer``
    one command per 1 / ``sample_rate`` s of wall time.

QoS: RELIABLE, KEEP_LAST 1000 (matches the simulator's lockstep command
subscription and the driver's best-effort one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from maglev_ros.excitation import (
    PATTERNS,
    SIGNALS,
    apply_pattern,
    excitation,
    pattern_signals,
)
from maglev_ros.nodes import contract

__all__ = [
    'ExcitationConfig',
    'ExcitationNode',
    'ExcitationParameterError',
    'build_config',
    'commands_of',
    'main',
]

NODE_NAME = 'maglev_excitation'
TRIGGERS = ('sample', 'timer')


class ExcitationParameterError(ValueError):
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


_PARAMETERS = {
    'signal': ('prbs', 'prbs, random_binary, multisine or chirp'),
    'amplitude': (0.5, 'peak of each signal, A'),
    'band': ([0.0, 1.0], 'pass band (low, high) as fractions of Nyquist'),
    'pattern': ('pairs', 'coil pattern: pairs, x_pair, y_pair, independent or common'),
    'offset': ([0.0, 0.0, 0.0, 0.0], 'currents added to every command, A (x+ x- y+ y-)'),
    'seed': (0, 'seed of the signals'),
    'length': (8191, 'samples per period'),
    'cycles': (0, 'periods to send (0: forever); then offset only'),
    'trigger': ('sample', 'sample: one command per maglev/currents message; timer: wall clock'),
    'sample_rate': (5000.0, 'timer trigger: commands per second, Hz'),
    'max_commands': (0, 'commands to publish, then none (0: no limit; lockstep: exact samples)'),
}


def build_config(values: dict) -> ExcitationConfig:
    """Validate raw parameter values.

    Parameters
    ----------
    values : dict
        Parameter name to value.

    Returns
    -------
    ExcitationConfig

    Raises
    ------
    ExcitationParameterError
        Naming the first invalid parameter and its value.
    """

    def choice(name, allowed):
        if values[name] not in allowed:
            raise ExcitationParameterError(
                f'{name} must be one of {", ".join(allowed)}, got {values[name]!r}'
            )
        return values[name]

    def integer(name, low):
        value = values[name]
        if not isinstance(value, int) or value < low:
            raise ExcitationParameterError(f'{name} must be an integer >= {low}, got {value!r}')
        return value

    amplitude = values['amplitude']
    if not (isinstance(amplitude, float) and math.isfinite(amplitude) and amplitude >= 0):
        raise ExcitationParameterError(
            f'amplitude must be a finite number >= 0, got {amplitude!r}'
        )
    band = tuple(float(b) for b in values['band'])
    if len(band) != 2 or not (0.0 <= band[0] < band[1] <= 1.0):
        raise ExcitationParameterError(
            f'band must be [low, high] with 0 <= low < high <= 1, got {list(band)}'
        )
    offset = tuple(float(v) for v in values['offset'])
    if len(offset) != 4 or not all(math.isfinite(v) for v in offset):
        raise ExcitationParameterError(f'offset must be 4 finite currents, got {list(offset)}')
    rate = values['sample_rate']
    if not (isinstance(rate, float) and math.isfinite(rate) and rate > 0):
        raise ExcitationParameterError(f'sample_rate must be a finite number > 0, got {rate!r}')
    return ExcitationConfig(
        signal=choice('signal', SIGNALS),
        amplitude=amplitude,
        band=band,
        pattern=choice('pattern', PATTERNS),
        offset=offset,
        seed=integer('seed', 0),
        length=integer('length', 1),
        cycles=integer('cycles', 0),
        trigger=choice('trigger', TRIGGERS),
        sample_rate=rate,
        max_commands=integer('max_commands', 0),
    )


def commands_of(cfg: ExcitationConfig) -> np.ndarray:
    """One period of coil commands of a configuration, shape (length, 4), A.

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
        self.config = cfg = build_config(contract.declare_parameters(self, _PARAMETERS))
        self.commands = commands_of(cfg)
        self._rest = [float(v) for v in cfg.offset]
        self._rows = self.commands.tolist()
        self.sent = 0
        self._msg = Float64MultiArray()
        self._pub = self.create_publisher(
            Float64MultiArray, contract.COMMAND_TOPIC, contract.LOCKSTEP_COMMAND_QOS
        )
        if cfg.trigger == 'sample':
            self.create_subscription(
                JointState, contract.CURRENTS_TOPIC, self._on_sample, contract.SENSOR_QOS, raw=True
            )
        else:
            self.create_timer(1.0 / cfg.sample_rate, self.publish_next)
        self.get_logger().info(
            f'{cfg.signal}, {cfg.amplitude:g} A, band {list(cfg.band)}, pattern {cfg.pattern}, '
            f'{cfg.length} samples x {cfg.cycles or "inf"}, seed {cfg.seed}, '
            f'trigger {cfg.trigger}'
        )

    @property
    def finished(self) -> bool:
        """True once all cycles were sent (offset only from then on)."""
        return bool(self.config.cycles) and self.sent >= self.config.cycles * self.config.length

    @property
    def exhausted(self) -> bool:
        """True once ``max_commands`` commands were published (nothing more is sent)."""
        return bool(self.config.max_commands) and self.sent >= self.config.max_commands

    def publish_next(self) -> None:
        """Publish the next command of the sequence (nothing once ``max_commands`` are sent)."""
        if self.exhausted:
            return
        if self.finished:
            data = self._rest
        else:
            data = self._rows[self.sent % self.config.length]
        self._msg.data = data
        self._pub.publish(self._msg)
        self.sent += 1

    def _on_sample(self, _raw: bytes) -> None:
        self.publish_next()


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
    return contract.run_nodes([ExcitationNode], args, NODE_NAME, (ExcitationParameterError,))


if __name__ == '__main__':
    raise SystemExit(main())
