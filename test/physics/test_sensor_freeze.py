"""Sensor freeze injection in the simulator: scheduled and seeded random freezes."""

import numpy as np
import pytest

from maglev_ros.physics import SensorEffects, SensorFreeze, Simulator

RATE = 5000.0


def _readings(model, freeze, n=400, seed=5):
    sim = Simulator(
        model, RATE, sensor=SensorEffects(1e-4, 0.098e-3, 0.0, 1), seed=seed, freeze=freeze
    )
    ys = [sim.reset()]
    ys += [sim.step(np.zeros(4)) for _ in range(n)]
    return np.array(ys).reshape(n + 1, -1, 3)


def test_scheduled_freeze_repeats_one_sensor_for_its_window(v2):
    free = _readings(v2, None)
    frozen = _readings(v2, SensorFreeze(schedule=((1, 0.02, 0.01),)))
    start, stop = int(0.02 * RATE), int(0.03 * RATE)  # 100 .. 149 at the sensor, +1 delay
    same = np.all(frozen[1:, 1] == frozen[:-1, 1], axis=1)  # reading n equals reading n-1
    assert np.all(same[start:stop]) and not same[start - 1] and not same[stop + 1]
    assert np.array_equal(
        frozen[start + 1 : stop + 1, 1], np.repeat(free[start : start + 1, 1], 50, 0)
    )
    # the other sensors and the rest of the run are untouched (noise stream unchanged)
    assert np.array_equal(frozen[:, [0, 2]], free[:, [0, 2]])
    assert np.array_equal(frozen[stop + 1 :, 1], free[stop + 1 :, 1])


def test_random_freezes_are_seeded_and_last_their_length(v2):
    freeze = SensorFreeze(rate=20.0, length=20)
    a = _readings(v2, freeze, n=2500)
    b = _readings(v2, freeze, n=2500)
    assert np.array_equal(a, b)
    for sensor in range(3):
        same = np.all(a[1:, sensor] == a[:-1, sensor], axis=1).astype(int)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], same, [0]])))
        runs = edges[1::2] - edges[::2]
        assert np.sum(runs >= 20) >= 3  # about 10 freezes expected per sensor in 0.5 s
        assert np.max(runs) < 40


def test_frozen_sensors_property_and_validation(v2):
    sim = Simulator(v2, RATE, freeze=SensorFreeze(schedule=((2, 0.0, 1.0),)))
    sim.reset()
    sim.step(np.zeros(4))
    assert sim.frozen_sensors == (2,)
    with pytest.raises(ValueError, match='names sensor 5'):
        Simulator(v2, RATE, freeze=SensorFreeze(schedule=((5, 0.0, 1.0),)))
    with pytest.raises(ValueError, match='schedule entries must be'):
        SensorFreeze(schedule=((1, 0.0),))
    with pytest.raises(ValueError, match='rate must be >= 0'):
        SensorFreeze(rate=-1.0)
