"""Static calibration recovers a perturbed plant from simulated data (magnet absent and fixed)."""

from __future__ import annotations

import numpy as np
import pytest

from maglev_ros.greybox import GreyBoxError, calibrate_static, write_parameters
from maglev_ros.physics import MaggyModel, Simulator, load_parameters, make_model

from .plant import NOISE, experiment, nominal_vector, truth

FREE = [
    'coil*.gain',
    'sensor1.x',
    'sensor2.y',
    'sensor0.z',
    'sensor1.gain_z',
    'sensor0.offset_z',
    'sensor2.offset_x',
    'pm0.polarization',
    'magnet.polarization',
    'magnet.mass',
]


@pytest.fixture(scope='module')
def calibration():
    vector = nominal_vector().with_free(FREE)
    return calibrate_static(vector, [experiment('absent'), experiment('fixed')])


def _true_value(name):
    return truth().get(name, nominal_vector()[name].nominal)


def test_recovers_every_identified_parameter(calibration):
    cal = calibration
    assert cal.delays == (1, 1)  # the simulator's sensor delay, found from the data
    board = [n for n in cal.names if not n.startswith('pose')]
    assert len(board) == 12  # every free board parameter but the mass
    for name in board:
        est, sd, true = cal.estimate[name], cal.std[name], _true_value(name)
        assert abs(est - true) <= 3 * sd, (name, est, true, sd)
        if name.endswith(('polarization', 'gain')) or '.gain_' in name:
            assert abs(est - true) <= 0.01 * abs(true), (name, est, true)
        elif name.split('.')[1] in ('x', 'y', 'z'):
            assert abs(est - true) <= 50e-6, (name, est, true)
        # and the estimate moved from nominal towards the truth where the plant differs
        nominal = nominal_vector()[name].nominal
        if true != nominal:
            assert abs(est - true) < abs(nominal - true), name
    # the held magnet: the simulator held it at the plant's own equilibrium
    assert abs(cal.estimate['pose0.x']) <= 3 * cal.std['pose0.x']
    assert cal.std['magnet.polarization'] > 0 and np.all(np.isfinite(cal.correlation))


def test_mass_is_reported_unidentifiable(calibration):
    (item,) = calibration.identifiability.unidentified
    assert item.name == 'magnet.mass' and item.reason == 'no effect'
    assert 'magnet.mass' not in calibration.names
    assert calibration.estimate['magnet.mass'] == nominal_vector()['magnet.mass'].nominal
    assert 'not identifiable' in item.line()


def test_calibrated_set_fits_validation_data_better(calibration):
    for nominal, calibrated in zip(
        calibration.validation_nominal, calibration.validation_calibrated, strict=True
    ):
        assert calibrated.total_rms < 0.2 * nominal.total_rms
        assert calibrated.total_rms < 1.05 * NOISE  # down to the sensor noise
        assert calibrated.mean_fit > nominal.mean_fit
    assert 0.9 < calibration.chi2_per_dof < 1.1


def test_offsets_and_magnet_polarisations_confounded():
    vector = nominal_vector().with_free(['sensor*.offset_*', 'pm*.polarization', 'coil0.gain'])
    cal = calibrate_static(vector, [experiment('absent')])
    lost = {u.name: u for u in cal.identifiability.unidentified}
    assert len(lost) == 4  # four polarisations against nine offsets of a constant field
    for item in lost.values():
        assert item.reason == 'combination' and item.partners
    assert cal.identifiability.rank == len(cal.names)
    # the plant's other differences are not free here: better than nominal, not noise level
    assert cal.validation_calibrated[0].total_rms < cal.validation_nominal[0].total_rms


def test_calibrated_file_loads_like_a_preset(calibration, tmp_path):
    path = write_parameters(calibration.params, tmp_path / 'board.yaml', ['a comment'])
    loaded = load_parameters(path)
    a, b = MaggyModel(calibration.params), make_model(str(path))
    x = a.hover_state(0.035)
    u = np.array([0.3, -0.2, 0.5, 0.1])
    assert np.array_equal(a.measurement(x, u), b.measurement(x, u))
    assert np.array_equal(a.dynamics(x, u), b.dynamics(x, u))
    assert loaded.solenoid_radius_correction == calibration.params.solenoid_radius_correction
    sim = Simulator(b, magnet='fixed', x0=x)
    assert np.allclose(sim.step(u), b.measurement(x, u))


def test_bad_input_is_named():
    vector = nominal_vector()
    with pytest.raises(GreyBoxError, match='no parameter matches'):
        vector.with_free(['coil9.gain'])
    with pytest.raises(GreyBoxError, match='exclude its nominal value'):
        vector.with_bounds('magnet.polarization', -0.9, -0.5)
    with pytest.raises(GreyBoxError, match='no free parameter'):
        calibrate_static(vector, [experiment('absent')])
    with pytest.raises(GreyBoxError, match='do not vary independently'):
        exp = experiment('absent')
        same = type(exp)(np.repeat(exp.u[:, :1], 4, axis=1), exp.y, 'absent', 'same currents')
        calibrate_static(vector.with_free(['coil0.gain']), [same])


def _freeze(exp, seed=4, runs=150, length=20):
    """The plant's readings with sensors frozen now and then (one reading held ``length``)."""
    rng = np.random.default_rng(seed)
    y = exp.y.copy()
    free_from = [1, 1, 1]  # a frozen sensor cannot freeze again before its reset
    for start in np.sort(rng.integers(1, exp.samples - length, runs)):
        k = int(rng.integers(0, 3))
        if start >= free_from[k]:
            y[start : start + length, 3 * k : 3 * k + 3] = y[start - 1, 3 * k : 3 * k + 3]
            free_from[k] = start + length + 1
    return type(exp)(exp.u, y, exp.magnet, 'frozen sensors', exp.Ts)


def test_frozen_sensor_readings_are_left_out():
    clean = experiment('absent')
    frozen = _freeze(clean)
    marked = frozen.frozen()
    assert marked.sum() > 1000 and not clean.frozen().any()
    # noise-free readings under held currents repeat exactly: that is no freeze
    exact = clean.u @ np.random.default_rng(0).normal(size=(4, 9))
    assert not type(clean)(clean.u, exact, 'absent').frozen().any()
    vector = nominal_vector().with_free(FREE[:-2])  # the magnet does not matter here
    lines = []
    cal = calibrate_static(vector, [frozen], progress=lines.append)
    assert any('readings of a frozen sensor left out' in line for line in lines)
    assert 0.9 < cal.chi2_per_dof < 1.1
    for name in cal.names:
        assert abs(cal.estimate[name] - _true_value(name)) <= 3 * cal.std[name], name
    assert np.all(np.abs(cal.noise[0] / NOISE - 1) < 0.05)  # the sensor noise, nothing more
    # kept, the frozen readings fit no static model: they look like extra noise
    kept = calibrate_static(vector, [frozen], frozen_run=0)
    assert np.mean(kept.noise[0]) > 1.3 * NOISE
