"""The simulated closed loop in real time, built from plain settings.

What a loop process hosts when its plant is the simulator: the believed model,
the simulated plant (optionally with another magnet: model mismatch), the
estimator at the sample rate and the controller at the control rate, as a
:class:`~maglev_ros.loop.ControlLoop` on a
:class:`~maglev_ros.loop.PacedSimulatedPlant`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .control_loop import ControlLoop
from .paced import PacedSimulatedPlant

__all__ = ['SimulatedLoopSettings', 'build_simulated_loop']


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
    """Build the loop and its plant.

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
    from ..control import ControllerConfig, make_controller
    from ..estimation import EstimatorConfig, make_estimator
    from ..physics import CoilDynamics, SensorEffects, Simulator, linearize, make_model

    burst = s.sample_rate / s.control_rate
    if abs(burst - round(burst)) > 1e-9 or round(burst) < 1:
        raise ValueError(
            f'control_rate must divide sample_rate ({s.sample_rate:g} Hz), '
            f'got {s.control_rate:g} Hz'
        )
    model = make_model(s.params)
    linear = linearize(model)
    p = model.params
    magnet = dataclasses.replace(
        p.magnet,
        polarization=p.magnet.polarization * s.plant_polarization,
        mass=p.magnet.mass * s.plant_mass,
    )
    plant_model = make_model(p.replace(magnet=magnet, solenoid_radius_correction=model.correction))
    simulator = Simulator(
        plant_model,
        s.sample_rate,
        coil=CoilDynamics.from_parameters(plant_model.params) if s.coil_dynamics else None,
        sensor=SensorEffects(s.sensor_noise, s.sensor_quantization, 0.0, s.sensor_delay),
        seed=s.seed,
    )
    controller = make_controller(
        model,
        ControllerConfig(
            mode=s.mode,
            sample_rate=s.control_rate,
            command_delay=s.command_delay,
            coil_dynamics=s.coil_dynamics,
        ),
        linear=linear,
    )
    estimator = None
    if s.mode == 'lqr':
        config = EstimatorConfig(
            filter=s.filter,
            sample_rate=s.sample_rate,
            sensor_delay=s.sensor_delay,
            bias_states=True,  # a static field error (mismatch, offsets) is not a tilt
        )
        estimator = make_estimator(model, config, linear=linear)
    timing = {k: v for k, v in (('clock', clock), ('sleep', sleep)) if v is not None}
    plant = PacedSimulatedPlant(simulator, round(burst), **timing)
    loop = ControlLoop(
        plant, controller, estimator, command_delay=s.command_delay, observers=observers
    )
    loop.warm_up()
    return loop, plant
