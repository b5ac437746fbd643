import numpy as np
import pytest
from scipy.io import loadmat

from maglev_ros.sysid import armax, bj, export_mat, load_model, save_model

from .systems import C_ARMAX, simulate_mimo_armax, simulate_siso


@pytest.mark.parametrize('suffix', ['.json', '.yaml'])
def test_round_trip(tmp_path, suffix):
    data = simulate_mimo_armax(3000, 1)
    model = armax(data, [[2, 2], [0, 2]], [[1, 1], [0, 1]], [1, 1], 1)
    loaded = load_model(save_model(model, tmp_path / f'm{suffix}'))
    assert loaded.structure == 'armax'
    assert np.array_equal(loaded.theta, model.theta)
    assert np.array_equal(loaded.orders.na, model.orders.na)
    assert np.allclose(loaded.covariance, model.covariance)
    assert np.allclose(loaded.simulate(data), model.simulate(data))
    assert np.allclose(loaded.report.fit, model.report.fit)
    assert str(loaded) == str(model)


def test_mat_export_has_polynomials(tmp_path):
    model = bj(
        simulate_siso(3000, 2, A=np.ones(1), C=C_ARMAX, F=np.array([1, -0.5])), 2, 1, 0, 1, 1
    )
    path = export_mat(model, tmp_path / 'm.mat')
    content = loadmat(path)
    assert content['Ts'][0, 0] == model.Ts
    assert np.allclose(content['F'][0, 0].ravel(), model.polynomial('F'))
    assert np.allclose(content['B'][0, 0].ravel(), model.polynomial('B'))
    assert content['nb'][0, 0] == 2
    assert save_model(model, tmp_path / 'n.mat').exists()


def test_io_errors(tmp_path):
    model = armax(simulate_siso(500, 0, C=C_ARMAX), 2, 2, 1)
    with pytest.raises(ValueError, match='extension must be'):
        save_model(model, tmp_path / 'm.txt')
    with pytest.raises(ValueError, match='does not exist'):
        load_model(tmp_path / 'none.json')
    (tmp_path / 'x.json').write_text('{"a": 1}')
    with pytest.raises(ValueError, match='is not a maglev_ros sysid model file'):
        load_model(tmp_path / 'x.json')
