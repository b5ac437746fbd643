"""Sensor model h(x, u): field sum, mounting rotation/gain/offset, all field models."""

import numpy as np
import pytest

from maglev_ros.physics.model import MaggyModel, make_model
from maglev_ros.physics.parameters import Sensor, load_parameters


def test_reading_is_base_plus_feedthrough_plus_magnet(v2, v2_equilibrium):
    u = np.array([0.5, -0.2, 0.1, 0.3])
    positions = np.array([s.position for s in v2.params.sensors])
    expected = v2.field_at(positions, u) + v2.magnet_field_at(positions, v2_equilibrium)
    np.testing.assert_allclose(
        v2.measurement(v2_equilibrium, u), expected.ravel(), rtol=1e-12, atol=1e-15
    )
    # the solenoids feed through linearly in the currents
    y0 = v2.measurement(v2_equilibrium)
    y1 = v2.measurement(v2_equilibrium, u)
    y2 = v2.measurement(v2_equilibrium, 2 * u)
    np.testing.assert_allclose(y2 - y0, 2 * (y1 - y0), rtol=1e-9, atol=1e-15)


def test_mounting_rotation_gain_and_offset():
    params = load_parameters('maggy_v2')
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    mounted = Sensor(
        position=params.sensors[1].position,
        rotation=quarter,
        gain=np.array([2.0, 1.0, 0.5]),
        offset=np.array([1e-3, 0.0, -1e-3]),
    )
    plain = MaggyModel(params.replace(sensors=(params.sensors[1],)))
    model = MaggyModel(params.replace(sensors=(mounted,)))
    x = plain.hover_state(0.0365)
    b = plain.measurement(x)
    reading = model.measurement(x)
    expected = np.array([2.0, 1.0, 0.5]) * (quarter.T @ b) + [1e-3, 0.0, -1e-3]
    np.testing.assert_allclose(reading, expected, rtol=1e-14)


def test_any_number_of_sensors():
    params = load_parameters('maggy_v4')
    many = tuple(Sensor(position=np.array([0.01 * k, -0.005 * k, 0.0])) for k in range(7))
    model = MaggyModel(params.replace(sensors=many))
    y = model.measurement(model.hover_state(0.03))
    assert y.shape == (21,) and np.all(np.isfinite(y))


@pytest.mark.parametrize('field', ['accurate', 'filament'])
def test_other_field_models_read_finite_values_close_to_fast(field):
    fast = make_model('maggy_v2')
    other = make_model('maggy_v2', field=field)
    x = fast.hover_state(0.0365)
    u = np.array([1.0, -1.0, 0.5, 0.0])
    y_fast, y_other = fast.measurement(x, u), other.measurement(x, u)
    assert np.all(np.isfinite(y_other))
    assert np.linalg.norm(y_other - y_fast) < 0.5 * np.linalg.norm(y_fast)
