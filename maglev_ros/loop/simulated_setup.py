"""The simulated closed loop in real time, built from plain settings.

What a loop process hosts when its plant is the simulator: the believed model,
the simulated plant (optionally with another magnet: model mismatch), the
estimator at the sample rate and the controller at the control rate, as a
:class:`~maglev_ros.loop.ControlLoop` on a
:class:`~maglev_ros.loop.PacedSimulatedPlant`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .control_loop import ControlLoop
from .paced import PacedSimulatedPlant

__all__ = ['SimulatedLoopSettings', 'build_loop', 'build_simulated_loop', 'plant_health']


@dataclass(frozen=True)
class SimulatedLoopSettings:
    """What the simulated real-time loop runs.

    Attributes
    ----------
    params : str
        Parameter set the estimator and the controller believe (``maggy_v2``,
        ``maggy_v4`` or a YAML path).
    sample_rate : float
        Samples per second, Hz (the board: 5000).
    control_rate : float
        Commands per second, Hz; divides ``sample_rate``.
    filter : str
        ``kf``, ``ekf`` or ``ukf``.
    mode : str
        ``lqr`` or ``pd``.
    command_delay : int
        Control periods a command waits before it drives the coils, in the
        loop and in the LQR's design.
    sensor_noise : float
        T rms per axis.
    sensor_quantization : float
        T per LSB (0: none).
    sensor_delay : int
        Samples.
    coil_dynamics : bool
        Coil L/R lag in the plant.
    seed : int
        Sensor-noise seed.
    plant_polarization, plant_mass : float
        The simulated magnet's polarisation and mass as factors of the
        believed set's (1: no model mismatch).
    """

    params: str = 'maggy_v2'
    sample_rate: float = 5000.0
    control_rate: float = 1000.0
    filter: str = 'kf'
    mode: str = 'lqr'
    command_delay: int = 0
    sensor_noise: float = 1.0e-4
    sensor_quantization: float = 0.098e-3
    sensor_delay: int = 1
    coil_dynamics: bool = True
    seed: int = 0
    plant_polarization: float = 1.0
    plant_mass: float = 1.0

    @property
    def burst(self) -> int:
        """Samples per control period."""
        return int(round(self.sample_rate / self.control_rate))


def build_simulated_loop(
    s: SimulatedLoopSettings, observers=(), clock=None, sleep=None
) -> tuple[ControlLoop, PacedSimulatedPlant]:
    """Build the loop and its plant (:func:`~maglev_ros.loop.lab.build_lab_loop` builds them).

    The estimator estimates sensor offsets (``bias_states``: a magnet other
    than the believed one is not taken for a tilt) and a loop far behind the
    clock skips ahead (overruns counted).

    Parameters
    ----------
    s : SimulatedLoopSettings
    observers : iterable
        The loop's observers (:class:`~maglev_ros.loop.ControlLoop`).
    clock, sleep : callable, optional
        The plant's clock (default the wall clock).

    Returns
    -------
    (ControlLoop, PacedSimulatedPlant)

    Raises
    ------
    ValueError
        If the control rate does not divide the sample rate, or the set
        cannot be loaded or controlled (naming the problem).
    """
    from .lab import build_lab_loop

    timing = {k: v for k, v in (('clock', clock), ('sleep', sleep)) if v is not None}
    loop = build_lab_loop(_lab_settings(s), observers=observers, **timing)
    return loop, loop.plant


def _lab_settings(s: SimulatedLoopSettings):
    """Return the lab builder's settings of the loop node's: real time, bias states."""
    from .lab import LabSettings

    return LabSettings(
        params=s.params,
        sample_rate=s.sample_rate,
        control_rate=s.control_rate,
        noise=s.sensor_noise,
        quantization=s.sensor_quantization,
        sensor_delay=s.sensor_delay,
        coil_dynamics=s.coil_dynamics,
        field_model='fast',
        seed=s.seed,
        filter=s.filter,
        realtime=True,
        mode=s.mode,
        bias_states=True,
        plant_polarization=s.plant_polarization,
        plant_mass=s.plant_mass,
        command_delay=s.command_delay,
        skip_ahead=True,
    )


def build_loop(s: SimulatedLoopSettings, board: dict | None = None):
    """Build the loop node's loop on the simulator, or on a V2x board.

    Parameters
    ----------
    s : SimulatedLoopSettings
        The loop's settings (the simulator's apply without a board).
    board : dict, optional
        ``port``, ``n_sensors``, ``command_timeout`` of a V2x board: its
        stream paces the loop (``sample_rate / control_rate`` samples a read).

    Returns
    -------
    (ControlLoop, plant)

    Raises
    ------
    ValueError
        If the settings cannot be built (named).
    LinkError
        If the board's port cannot be opened.
    """
    if board is None:
        return build_simulated_loop(s)
    from .board import BOARD_SAMPLE_RATE, BoardPlant
    from .lab import build_lab_loop

    if s.sample_rate != BOARD_SAMPLE_RATE:
        raise ValueError(
            f'a V2x board samples at {BOARD_SAMPLE_RATE:g} Hz: sample_rate must be that, '
            f'got {s.sample_rate:g}'
        )
    plant = BoardPlant(
        board['port'],
        board['n_sensors'],
        burst=s.burst,
        command_timeout=board['command_timeout'],
    )
    # the board's own latency is designed for (command_delay None), its plant is the board
    lab = replace(_lab_settings(s), command_delay=None)
    loop = build_lab_loop(lab, plant=plant)
    plant.open()
    return loop, plant


def plant_health(plant) -> dict[str, object]:
    """Return the plant's counts for the diagnostics: samples, real-time factor, link counts.

    Parameters
    ----------
    plant : PacedSimulatedPlant or BoardPlant
    """
    simulator = getattr(plant, 'simulator', None)
    if simulator is not None:
        return {
            'samples': simulator.samples,
            'real_time_factor': f'{plant.real_time_factor:.3f}',
            'overruns': plant.overruns,
        }
    return dict(plant.counters)
