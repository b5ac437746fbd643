"""The named parameter vector: names, patterns, bounds, and the parameter set it maps onto."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_ros.greybox import GreyBoxError, calibrate_static, parameter_vector, write_parameters
from maglev_ros.physics import MaggyModel, load_parameters

from .plant import experiment, nominal_vector


def test_every_parameter_maps_onto_the_file_and_back(tmp_path):
    vector = nominal_vector()
    assert len(vector) == 2 + 4 + 4 + 1 + 1 + 3 * 12
    changed = {
        'magnet.polarization': -1.05,
        'magnet.mass': 0.08,
        'pm2.polarization': 1.2,
        'coil3.gain': 1.1,
        'solenoid_radius_correction': 0.6,
        'coils.resistance': 3.5,
        'sensor2.z': 0.0004,
        'sensor1.gain_y': 0.97,
        'sensor0.offset_x': -2e-4,
        'sensor1.tilt_z': 0.02,
    }
    params = vector.apply(changed)
    assert params.magnet.polarization == -1.05 and params.magnet.mass == 0.08
    assert params.permanent_magnets.polarization[2] == 1.2
    assert params.solenoids.turns[3] == pytest.approx(480 * 1.1)
    assert params.solenoid_radius_correction == 0.6 and params.coils.resistance == 3.5
    assert params.sensors[2].position[2] == 0.0004 and params.sensors[1].gain[1] == 0.97
    assert params.sensors[0].offset[0] == -2e-4
    rot = params.sensors[1].rotation
    assert rot[1, 0] == pytest.approx(np.sin(0.02)) and np.allclose(rot @ rot.T, np.eye(3))
    loaded = load_parameters(write_parameters(params, tmp_path / 'p.yaml'))
    back = parameter_vector(loaded)
    for name, value in changed.items():
        if name not in ('coil3.gain', 'sensor1.tilt_z'):  # these live in turns and rotation
            assert back[name].nominal == value, name
    assert loaded.solenoids.turns[3] == params.solenoids.turns[3]
    assert np.array_equal(loaded.sensors[1].rotation, rot)
    x = MaggyModel(params).hover_state(0.036)
    u = np.array([0.2, -0.4, 0.1, 0.3])
    assert np.array_equal(
        MaggyModel(params).measurement(x, u), MaggyModel(loaded).measurement(x, u)
    )


def test_patterns_bounds_and_nominal_values():
    vector = nominal_vector()
    assert vector.expand(['sensor*.offset_z', 'coil1.gain']) == (
        'coil1.gain',
        'sensor0.offset_z',
        'sensor1.offset_z',
        'sensor2.offset_z',
    )
    narrowed = vector.with_bounds('coil0.gain', 0.9, 1.1)
    assert (narrowed['coil0.gain'].lower, narrowed['coil0.gain'].upper) == (0.9, 1.1)
    with pytest.raises(GreyBoxError, match='lower < upper'):
        vector.with_bounds('coil0.gain', 1.1, 0.9)
    with pytest.raises(GreyBoxError, match="unknown parameter 'coil0.gian'"):
        vector['coil0.gian']
    moved = vector.with_nominal({'coil0.gain': 2.0})
    assert moved['coil0.gain'].nominal == 2.0 and moved['coil0.gain'].upper == 2.0
    assert vector['sensor1.x'].display(0.0153) == '15.3 mm'
    assert vector['coil0.gain'].display(1.02) == '1.02'


def test_scipy_finite_differences_reach_the_same_estimate():
    vector = nominal_vector().with_free(['coil*.gain', 'sensor1.x'])
    exp = experiment('absent', 4000)
    ours = calibrate_static(vector, [exp])
    plain = calibrate_static(vector, [exp], jacobian='2-point')
    for name in ours.names:
        assert abs(ours.estimate[name] - plain.estimate[name]) < 0.05 * ours.std[name], name
