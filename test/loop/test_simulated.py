"""The simulator as a lockstep plant, and its averaged samples."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_ros.loop import SimulatedPlant
from maglev_ros.physics import CoilDynamics, SensorEffects, Simulator, make_model


def _simulator(v2):
    return Simulator(v2, 5000.0, coil=CoilDynamics.from_parameters(v2.params),
                     sensor=SensorEffects(1e-4), seed=5)  # fmt: skip


def test_an_averaged_sample_is_the_mean_of_a_group_where_the_command_lands_at_the_offset():
    v2 = make_model('maggy_v2')
    plant = SimulatedPlant(_simulator(v2), average=5, offset=2)
    reference = _simulator(v2)
    assert plant.sample_rate == pytest.approx(1000.0)
    first = plant.read()
    np.testing.assert_array_equal(first.readings[0], reference.reset())
    assert first.index.tolist() == [0] and first.stamps_ns.tolist() == [0]
    held = np.zeros(4)
    for m, command in enumerate(([0.2, 0.0, 0.0, 0.0], [0.0, 0.3, 0.0, 0.0]), start=1):
        plant.write(np.array(command), 0)
        rows = [(reference.step(held if i < 2 else command), reference.currents)
                for i in range(5)]  # fmt: skip
        held = np.array(command)
        block = plant.read()
        assert block.index.tolist() == [m] and block.stamps_ns.tolist() == [m * 1_000_000]
        np.testing.assert_allclose(block.readings[0], np.mean([r for r, _ in rows], axis=0))
        np.testing.assert_allclose(block.currents[0], np.mean([c for _, c in rows], axis=0))
        np.testing.assert_array_equal(block.states[0], reference.state)
    for bad in (-1, 5, True):
        with pytest.raises(ValueError, match='offset must be an integer from 0 to 4'):
            SimulatedPlant(_simulator(v2), average=5, offset=bad)
