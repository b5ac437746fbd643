"""The simulator's configuration and the physics simulator it builds, ROS-free.

:class:`SimulatorConfig` holds the simulator node's validated parameters
(the node's parameter table validates them one by one);
:func:`make_simulator` builds the :class:`~maglev_ros.physics.Simulator`,
with the checks that need the parameter set (sensor indices, initial state).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..topics import COMMAND_TOPIC
from .model import make_model
from .parameters import ParameterError
from .simulation import CoilDynamics, SensorEffects, Simulator

__all__ = [
    'SimulatorConfig',
    'SimulatorConfigError',
    'check_initial_state',
    'check_parameter_set',
    'check_sensor_indices',
    'make_simulator',
]


class SimulatorConfigError(ValueError):
    """A configuration does not fit its parameter set (the message names the value)."""


def check_initial_state(
    name: str, state: tuple[float, ...], error: type[ValueError] = SimulatorConfigError
) -> tuple[float, ...] | None:
    """Check an initial state: 12 finite numbers, or none (the first equilibrium).

    Parameters
    ----------
    name : str
        The parameter's name (for the message).
    state : tuple of float
        x y z alpha beta gamma vx vy vz wx wy wz (m, rad, m/s, rad/s), or empty.

    error : type, optional
        The exception raised (a node raises its own parameter error).

    Returns
    -------
    tuple of float or None
        The state, None when empty.

    Raises
    ------
    SimulatorConfigError (or ``error``)
        Naming the parameter and the value.
    """
    if state and (len(state) != 12 or not all(math.isfinite(v) for v in state)):
        raise error(
            f'{name} must be 12 finite numbers (x y z alpha beta gamma vx vy vz '
            f'wx wy wz), got {list(state)}'
        )
    return state or None


def check_sensor_indices(
    name: str, sensors: tuple[int, ...], error: type[ValueError] = SimulatorConfigError
) -> tuple[int, ...]:
    """Check sensor indices: distinct, >= 0 (the parameter set bounds them later).

    Parameters
    ----------
    name : str
        The parameter's name (for the message).
    sensors : tuple of int
        The indices.
    error : type, optional
        The exception raised (a node raises its own parameter error).

    Returns
    -------
    tuple of int

    Raises
    ------
    SimulatorConfigError (or ``error``)
        Naming the parameter and the value.
    """
    if any(k < 0 for k in sensors) or len(set(sensors)) != len(sensors):
        raise error(f'{name} must be distinct sensor indices >= 0, got {list(sensors)}')
    return sensors


def check_parameter_set(
    name: str, value: str, error: type[ValueError] = SimulatorConfigError
) -> str:
    """Check that a parameter set is named (a built-in set or a YAML path).

    Parameters
    ----------
    name : str
        The parameter's name (for the message).
    value : str
        The set.
    error : type, optional
        The exception raised (a node raises its own parameter error).

    Returns
    -------
    str

    Raises
    ------
    SimulatorConfigError (or ``error``)
        If it is empty.
    """
    if not value:
        raise error(f'{name} must name a parameter set, got an empty string')
    return value


@dataclass(frozen=True)
class SimulatorConfig:
    """Validated simulator parameters (meanings: the simulator node's parameter table).

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
    wait_for_controller : bool
        Real time: step from the first sample on only once a first command
        arrived and ``start_subscribers`` subscribers of ``maglev/currents``
        exist, so a free magnet does not fall before the controller is up.
    average : int
        Real time: steps per published sample, each sample the mean of their
        readings and currents, stamped at the last
        (:class:`~maglev_ros.physics.sample_average.SampleAverager`); 1: every
        step is published.
    start_reader : str
        Name of a node (a recorder, say) that must subscribe to the
        ``start_reader_topics`` before the run starts, so that what it records
        begins with their first messages; '' for none.
    start_reader_topics : tuple of str
        Those topics (default the commands).
    hold : float
        A free magnet is held at its initial state for this long after each
        start, s, then released (:class:`~maglev_ros.physics.Simulator`'s
        ``hold``); 0: free from the start.
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
    wait_for_controller: bool = False
    average: int = 1
    start_reader: str = ''
    start_reader_topics: tuple[str, ...] = (COMMAND_TOPIC,)
    hold: float = 0.0

    @property
    def _reader_wait(self) -> str:
        """The start_reader's wait, when there is one (real time waits only for a controller)."""
        if not self.start_reader or (self.mode == 'realtime' and not self.wait_for_controller):
            return ''
        return f' and for {self.start_reader} to read {", ".join(self.start_reader_topics)}'

    def summary(self, set_name: str, sensors: tuple[int, ...]) -> str:
        """One line saying what runs (the node logs it at start).

        Parameters
        ----------
        set_name : str
            The parameter set's name.
        sensors : tuple of int
            The sensors published (all of the set's when :attr:`sensors` is empty).
        """
        means = ''
        if self.average > 1:
            rate = self.sample_rate / self.average
            means = f' (published as means of {self.average}: {rate:g} Hz)'
        return (
            f'{set_name} ({self.field_model} field), magnet {self.magnet}, {self.mode} at '
            f'{self.sample_rate:g} Hz{means}'
            f', sensors {list(sensors)}, coil dynamics '
            f'{"on" if self.coil_dynamics else "off"}, sensor delay {self.sensor_delay}, '
            f'noise {self.sensor_noise:g} T, seed {self.seed}'
            f'{", paused" if self.start_paused else ""}'
            f'{", waiting for a first command" if self.wait_for_controller else ""}'
            f'{self._reader_wait}{self._hold_note}'
        )

    @property
    def _hold_note(self) -> str:
        """The free magnet's hold after the start, when there is one."""
        if self.hold > 0 and self.magnet == 'free':
            return f', the magnet held {self.hold:g} s after the start'
        return ''


def make_simulator(cfg: SimulatorConfig) -> Simulator:
    """Build the physics simulator of a configuration.

    Parameters
    ----------
    cfg : SimulatorConfig
        The validated parameters.

    Returns
    -------
    Simulator
        At its initial state.

    Raises
    ------
    SimulatorConfigError
        If the parameter set cannot be loaded, the options do not fit it, or
        ``average`` is asked in lockstep.
    """
    if cfg.average > 1 and cfg.mode != 'realtime':
        raise SimulatorConfigError(
            f'average {cfg.average} (published samples as means of steps) needs mode realtime, '
            f'got mode {cfg.mode!r}: set average 1 or mode realtime'
        )
    try:
        model = make_model(
            cfg.params, field=cfg.field_model, torque=cfg.torque, kinematics=cfg.kinematics
        )
    except (ParameterError, OSError, ValueError) as err:
        raise SimulatorConfigError(f'params {cfg.params!r}: {err}') from err
    n_sensors = len(model.params.sensors)
    bad = [k for k in cfg.sensors if k >= n_sensors]
    if bad:
        raise SimulatorConfigError(
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
            hold=cfg.hold,
        )
    except ValueError as err:
        raise SimulatorConfigError(f'initial_state / model: {err}') from err
