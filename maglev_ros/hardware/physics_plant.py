"""A board-emulator plant backed by the physics core's simulator.

``SimulatorPlant`` turns ``maglev_ros.physics.Simulator`` into the plant
callable the firmware emulators take: each call is one board sample
(200 us): the applied PWM counts become coil currents through a
``CurrentScaling`` (the steady-state current the driver assumes), the
simulator advances one sample with them, and its sensor reading (T) is
returned in millitesla, shape (n_sensors, 3).

The magnet is ``free`` (it levitates only if the host closes the loop; it
falls within a fraction of a second otherwise), ``fixed`` (held at its
start pose) or ``absent``. After a crash (the free magnet touched the base
or left the workspace) the magnet stays where it crashed: readings are then
the model's measurement at that pose with the applied currents, read through
the sensor effects (noise, quantisation) as before.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .scaling import CurrentScaling
from .v2x_stream import SAMPLE_PERIOD_US

__all__ = ['MAGNET_MODES', 'SimulatorPlant', 'make_simulator_plant']

MAGNET_MODES = ('free', 'fixed', 'absent')


class SimulatorPlant:
    """Plant for the firmware emulators that steps a physics simulator.

    Parameters
    ----------
    simulator : maglev_ros.physics.Simulator
        Sampling at the board's 5 kHz (one step per call).
    scaling : CurrentScaling
        PWM counts to coil current (A), the simulator's input.

    Raises
    ------
    ValueError
        If the simulator does not sample at 5 kHz.
    """

    def __init__(self, simulator, scaling: CurrentScaling) -> None:
        period_us = simulator.dt * 1e6
        if abs(period_us - SAMPLE_PERIOD_US) > 1e-6:
            raise ValueError(
                f'simulator must sample every {SAMPLE_PERIOD_US} us, got {period_us:g} us'
            )
        self.simulator = simulator
        self.scaling = scaling
        self.n_sensors = simulator.model.n_outputs // 3

    def reset(self) -> None:
        """Restart the simulator at its start state (a board power-up)."""
        self.simulator.reset()

    @property
    def crashed(self) -> bool:
        """Whether the free magnet crashed (then it stays at the crash pose)."""
        return self.simulator.crashed

    def __call__(self, pwm: ArrayLike, time: float) -> NDArray[np.float64]:
        """Advance one sample with the PWM counts (4,); return fields (n_sensors, 3) in mT."""
        current = self.scaling.to_current(pwm)
        sim = self.simulator
        if sim.crashed:
            pose = sim.crash_state if sim.crash_state is not None else sim.state
            # the sensors keep their noise: a noiseless reading repeated would also
            # trip the V4x firmware's freeze reset (160 ms without replies) every 20 samples
            reading = sim.observe(sim.model.measurement(pose, current))
        else:
            reading = sim.step(current)
        return np.asarray(reading, dtype=float).reshape(self.n_sensors, 3) * 1e3  # T -> mT


def make_simulator_plant(
    magnet: str = 'fixed',
    params: str = 'maggy_v2',
    scaling: CurrentScaling | None = None,
    sensor=None,
    seed: int | None = None,
) -> SimulatorPlant:
    """Build a ``SimulatorPlant`` from a physics parameter set.

    Parameters
    ----------
    magnet : {'free', 'fixed', 'absent'}
        The levitating magnet's mode (start pose: the model's equilibrium).
    params : str
        Preset name or YAML path of ``maglev_ros.physics.make_model``.
    scaling : CurrentScaling, optional
        PWM to current (default ``from_supply(12 V, 4 ohm)``, the driver's default).
    sensor : maglev_ros.physics.SensorEffects, optional
        Noise, quantisation and delay of the readings (default: ideal sensors).
    seed : int, optional
        Seed of the sensor noise.

    Returns
    -------
    SimulatorPlant
        A fresh plant (a new simulator at its start state).
    """
    if magnet not in MAGNET_MODES:
        raise ValueError(f'magnet must be one of {", ".join(MAGNET_MODES)}, got {magnet!r}')
    from maglev_ros.physics import Simulator, make_model  # heavy import: only when used

    model = make_model(params)
    simulator = Simulator(
        model, sample_rate=1e6 / SAMPLE_PERIOD_US, magnet=magnet, sensor=sensor, seed=seed
    )
    return SimulatorPlant(simulator, scaling or CurrentScaling.from_supply(12.0, 4.0))
