"""The closed loop on a V4x PC-control board, built from plain settings.

What runs the magnet on a current (V4x) board from a PC: the board's one
sensor and its processed field (:class:`~maglev_ros.estimation.EstimatorConfig`
``measurement='board'``), a KF with that measurement model at the loop's
sample rate, the LQR at the same rate, as a
:class:`~maglev_ros.loop.ControlLoop` on a
:class:`~maglev_ros.loop.v4x_pc_plant.V4xPcPlant`.

The board applies pair differences only (x+ gets ``p_x``, x- ``-p_x``): the
LQR's common-mode part (the same current in every coil, which acts on the
height z) cannot reach the coils and is dropped by the plant's guard. The
height is not controlled then; it is held by the base magnets (the z mode of
the model is an undamped oscillation, stable, not unstable as x and y are).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..hardware.scaling import V4X_PWM_FULL_SCALE, CurrentScaling
from .control_loop import ControlLoop
from .v4x_pc_plant import DEFAULT_RATE, V4xPcPlant

__all__ = ['V4xPcLoopSettings', 'board_model', 'build_v4x_pc_loop']


@dataclass(frozen=True)
class V4xPcLoopSettings:
    """What the loop on a V4x PC-control board runs.

    Attributes
    ----------
    params : str
        Parameter set the estimator and the controller believe (``maggy_v2``,
        ``maggy_v4`` or a YAML path).
    sensor : int
        Which sensor of the set the board reads (its mux channel 7).
    sample_rate : float
        Samples (and commands) per second, Hz.
    supply_voltage, coil_resistance : float
        V and ohm: the PWM scaling (255 counts at full duty).
    current_limit : float
        Largest commanded |current| per coil, A.
    bias_states : bool
        Estimate a constant offset per axis (the baseline's error, a
        feedthrough slope's error).
    coil_dynamics : bool
        The coils' L/R lag in the LQR design.
    command_delay : int
        Samples of command delay in the LQR design (the plant writes each
        command a fraction of a period after its sample: 0).
    sensor_noise : float
        T rms per axis the estimator assumes.
    """

    params: str = 'maggy_v2'
    sensor: int = 0
    sample_rate: float = DEFAULT_RATE
    supply_voltage: float = 12.0
    coil_resistance: float = 4.0
    current_limit: float = 1.0
    bias_states: bool = True
    coil_dynamics: bool = False
    command_delay: int = 0
    sensor_noise: float = 1.0e-4

    @property
    def scaling(self) -> CurrentScaling:
        """PWM counts per ampere of the board (255 counts at full duty)."""
        return CurrentScaling.from_supply(
            self.supply_voltage, self.coil_resistance, V4X_PWM_FULL_SCALE
        )


def board_model(params: str, sensor: int):
    """Return the physics model of ``params`` with only the board's sensor.

    Parameters
    ----------
    params : str
        Preset or YAML path.
    sensor : int
        Index of the sensor the board reads.

    Raises
    ------
    ValueError
        If the set has no such sensor.
    """
    from ..physics import load_parameters, make_model

    p = load_parameters(params)
    if not 0 <= sensor < len(p.sensors):
        raise ValueError(
            f'sensor must be 0 to {len(p.sensors) - 1} for {params!r}, got {sensor!r}'
        )
    return make_model(p.replace(sensors=(p.sensors[sensor],)))


def build_v4x_pc_loop(
    s: V4xPcLoopSettings, link, observers=(), clock=None, sleep=None
) -> tuple[ControlLoop, V4xPcPlant]:
    """Build the loop and its plant (the plant is not opened: :meth:`V4xPcPlant.open`).

    Parameters
    ----------
    s : V4xPcLoopSettings
    link : V4xPcLink
        The board's link.
    observers : iterable
        The loop's observers (:class:`~maglev_ros.loop.ControlLoop`).
    clock, sleep : callable, optional
        The plant's clock (default the wall clock).

    Returns
    -------
    (ControlLoop, V4xPcPlant)

    Raises
    ------
    ValueError
        If the set cannot be loaded or controlled, or a setting is out of range.
    """
    from ..control import ControllerConfig, make_controller
    from ..estimation import EstimatorConfig, make_estimator
    from ..physics import linearize

    model = board_model(s.params, s.sensor)
    linear = linearize(model)
    controller = make_controller(
        model,
        ControllerConfig(
            mode='lqr',
            sample_rate=s.sample_rate,
            command_delay=s.command_delay,
            sensor_delay=0,
            coil_dynamics=s.coil_dynamics,
            current_limit=s.current_limit,
        ),
        linear=linear,
    )
    estimator = make_estimator(
        model,
        EstimatorConfig(
            filter='kf',
            sample_rate=s.sample_rate,
            sensor_delay=0,
            sensor_noise=s.sensor_noise,
            bias_states=s.bias_states,
            measurement='board',
        ),
        linear=linear,
    )
    timing = {k: v for k, v in (('clock', clock), ('sleep', sleep)) if v is not None}
    plant = V4xPcPlant(link, s.scaling, s.current_limit, s.sample_rate, **timing)
    loop = ControlLoop(plant, controller, estimator, observers=observers)
    # compile the estimator's and the controller's kernels now, not in the first period
    x_hat = estimator.step(estimator.y_eq, estimator.u_eq)
    controller.command(0.0, x_hat, estimator.u_eq)
    loop.reset()
    return loop, plant
