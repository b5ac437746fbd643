"""The loop adapter: a reused loop runs as a fresh one; plant errors and delays reach the loop."""

from __future__ import annotations

import numpy as np

from maglev_ros.control import ControllerConfig
from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.study import loop_adapter
from maglev_ros.study.loop_adapter import loop_setup, simulate


def _fresh(values, seed, duration, **kwargs):
    """The same run on a loop built for it alone, as a user would."""
    setup = loop_setup(values)
    loop = make_closed_loop(
        setup.params,
        estimator=setup.estimator,
        controller=setup.controller,
        noise=setup.noise,
        quantization=setup.quantization,
        sensor_delay=setup.sensor_delay,
        seed=seed,
        **kwargs,
    )
    x0 = loop.simulator.model.hover_state(loop.z_eq)
    x0[0] += values.get('x0.x', 0.0)
    return loop.run(duration, x0=x0)


def test_a_reused_loop_gives_the_numbers_of_a_fresh_one():
    for controller in ('lqr', 'pd'):
        values = {'controller': controller, 'x0.x': 0.4e-3}
        simulate(values, 5, 0.1)  # the cached loop has run before, with another seed
        reused = simulate(values, 9, 0.1)
        fresh = _fresh(values, 9, 0.1)
        assert np.array_equal(reused.x, fresh.x), controller
        assert np.array_equal(reused.command, fresh.command), controller
        other = simulate(values, 10, 0.1)
        assert not np.array_equal(other.x, fresh.x)  # the seed reaches the noise


def test_the_cache_holds_one_loop_per_setup():
    loop_adapter._loops.clear()
    simulate({'controller': 'pd'}, 1, 0.01)
    simulate({'controller': 'pd', 'x0.x': 1e-4}, 2, 0.01)  # same set-up, another start
    assert len(loop_adapter._loops) == 1
    simulate({'controller': 'pd', 'sensor.noise': 2e-4}, 1, 0.01)
    assert len(loop_adapter._loops) == 2


def test_plant_errors_change_the_simulated_plant_only():
    base = simulate({'controller': 'pd'}, 1, 0.05)
    heavier = simulate({'controller': 'pd', 'plant.polarization': 0.1}, 1, 0.05)
    assert heavier.z_eq != base.z_eq  # the plant's equilibrium moved
    loop = loop_adapter._loops[loop_setup({'controller': 'pd', 'plant.polarization': 0.1})]
    believed = loop_adapter._believed('maggy_v2')[0]
    plant = loop.simulator.model
    assert plant.params.magnet.polarization == believed.params.magnet.polarization * 1.1
    assert plant.params.magnet.mass == believed.params.magnet.mass
    assert plant.correction == believed.correction
    moved = loop_adapter._plant(believed, (0, 0, 0, 1e-3, 0, 0, 0, 0, 2e-4))
    for s, s0 in zip(moved.params.sensors, believed.params.sensors, strict=True):
        assert np.allclose(s.position - s0.position, [1e-3, 0, 0])
        assert np.allclose(s.offset - s0.offset, [0, 0, 2e-4])


def test_the_loop_command_delay_is_applied_and_the_design_keeps_its_own():
    values = {'controller': 'lqr', 'loop.command_delay': 4}
    late = simulate(values, 3, 0.05)
    loop = loop_adapter._loops[loop_setup(values)]
    assert loop.command_delay == 4 and loop.controller.config.command_delay == 1
    fresh = _fresh({'controller': 'lqr'}, 3, 0.05)
    assert not np.array_equal(late.x, fresh.x)
    # a controller designed for the delay
    designed = loop_setup({'controller': 'lqr', 'controller.command_delay': 4}).controller
    assert designed == ControllerConfig(command_delay=4)
