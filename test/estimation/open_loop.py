"""The estimator tests' recorded open-loop run: one plant, one input sequence."""

import numpy as np

from maglev_ros.physics import CoilDynamics, SensorEffects, Simulator


def open_loop_run(plant, x_eq):
    """0.15 s of noisy, quantised, delayed readings and coil currents from a small offset.

    Parameters
    ----------
    plant : MaggyModel
        The simulated plant.
    x_eq : ndarray, shape (12,)
        The equilibrium the run starts near (20, -10, 30 um off).

    Returns
    -------
    tuple of ndarray
        Readings (N, 9), currents (N, 4), true states (N, 12), N = 750.
    """
    sim = Simulator(
        plant,
        5000.0,
        coil=CoilDynamics.from_parameters(plant.params),
        sensor=SensorEffects(1e-4, 0.098e-3, 0.0, 1),
        seed=3,
    )
    x0 = x_eq.copy()
    x0[:3] += [2e-5, -1e-5, 3e-5]
    rng = np.random.default_rng(4)
    y = sim.reset(x0)
    ys, cs, xs = [], [], []
    for _ in range(750):
        ys.append(y)
        cs.append(sim.currents)
        xs.append(sim.state)
        y = sim.step(rng.normal(scale=0.05, size=4))
    assert not sim.crashed
    return np.array(ys), np.array(cs), np.array(xs)
