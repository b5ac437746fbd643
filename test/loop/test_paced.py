"""The simulator paced by a clock, in the loop the loop node runs (5 kHz sensing, 1 kHz control).

A simulated clock stands in for the wall clock (its sleep advances it), so the
runs are exact and as fast as they compute.
"""

import numpy as np
import pytest

from maglev_ros.loop import PacedSimulatedPlant, SimulatedLoopSettings, build_simulated_loop
from maglev_ros.physics import Simulator, make_model


class Clock:
    """A clock whose sleep advances it."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now

    def sleep(self, seconds):
        self.now += seconds


def hold(settings, seconds):
    clock = Clock()
    states = []
    loop, plant = build_simulated_loop(
        settings, observers=[lambda s: states.append(s.state[:3])], clock=clock, sleep=clock.sleep
    )
    n = loop.run(int(seconds * settings.sample_rate))
    assert not loop.stopped, loop.reason
    p = np.array(states)[int(settings.sample_rate) :]  # after 1 s
    p[:, 2] -= p[:, 2].mean()
    return n, np.abs(p).max(axis=0), np.sqrt(np.mean(p**2, axis=0)), plant


@pytest.mark.parametrize(('polarization', 'mass'), [(1.0, 1.0), (1.1, 0.9), (0.9, 1.1)])
def test_the_composed_loop_holds_with_noise_and_a_mismatched_magnet(polarization, mass):
    settings = SimulatedLoopSettings(plant_polarization=polarization, plant_mass=mass)
    n, largest, rms = hold(settings, 3.0)[:3]
    assert n == 15000
    assert np.all(largest[:2] < 0.5e-3), largest
    assert np.all(rms < 0.1e-3), rms


def test_each_read_returns_one_control_period_and_a_late_loop_catches_up():
    clock = Clock()
    sim = Simulator(make_model('maggy_v2'), 5000.0)
    plant = PacedSimulatedPlant(sim, 5, clock=clock, sleep=clock.sleep, max_burst=20)
    first = plant.read()
    assert list(first.index) == [1, 2, 3, 4, 5] and clock.now == pytest.approx(0.001)
    clock.now += 0.0021  # the loop was late: 2 more periods fell due (and a part)
    late = plant.read()
    assert list(late.index) == list(range(6, 16)) and plant.overruns == 0
    clock.now += 1.0  # far behind: the plant skips ahead (the magnet does not wait)
    assert len(plant.read()) == 20 and plant.overruns == 1
    assert plant.real_time_factor == pytest.approx(sim.time / clock.now)


def test_the_control_rate_must_divide_the_sample_rate():
    with pytest.raises(ValueError, match=r'control_rate must divide sample_rate \(5000 Hz\)'):
        build_simulated_loop(SimulatedLoopSettings(control_rate=3000.0))
