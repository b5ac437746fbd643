"""Shared fixtures: models, linearisations and recorded open-loop data, built once."""

import numpy as np
import pytest

from maglev_ros.physics import CoilDynamics, SensorEffects, Simulator, linearize, make_model


@pytest.fixture(scope='session')
def v2():
    return make_model('maggy_v2')


@pytest.fixture(scope='session')
def v2_linear(v2):
    return linearize(v2)


@pytest.fixture(scope='session')
def v2_data(v2, v2_linear):
    """0.15 s of noisy, quantised, delayed readings and coil currents from a small offset.

    Returns (readings (N, 9), currents (N, 4), true states (N, 12)).
    """
    sim = Simulator(
        v2,
        5000.0,
        coil=CoilDynamics.from_parameters(v2.params),
        sensor=SensorEffects(1e-4, 0.098e-3, 0.0, 1),
        seed=3,
    )
    x0 = v2_linear.x_eq.copy()
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
