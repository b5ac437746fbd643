import numpy as np
import pytest
from scipy.io import savemat

from maglev_ros.sysid import DataFileError, load_data


@pytest.fixture
def channels():
    rng = np.random.default_rng(0)
    return rng.standard_normal((5, 50))  # one channel per row, as the lab's DATA


def test_mat_data_matrix_rows_counted_from_one(tmp_path, channels):
    path = tmp_path / 'data.mat'
    savemat(path, {'DATA': channels})
    d = load_data(path, Ts=2e-4, rows=([1, 2], [4, 5]))
    assert (d.ny, d.nu, d.N) == (2, 2, 50)
    assert np.allclose(d.y[:, 1], channels[1]) and np.allclose(d.u[:, 0], channels[3])
    assert load_data(path, Ts=2e-4, rows=([3], [5])).y[0, 0] == channels[2, 0]


def test_npz_with_y_u_and_ts(tmp_path, channels):
    path = tmp_path / 'd.npz'
    np.savez(path, y=channels[:2].T, u=channels[3:].T, Ts=0.01)
    d = load_data(path)
    assert d.Ts == 0.01 and (d.ny, d.nu) == (2, 2)
    assert load_data(path, Ts=0.5).Ts == 0.5


def test_csv_with_time_column(tmp_path):
    path = tmp_path / 'd.csv'
    t = np.arange(20) * 0.002
    table = np.column_stack([t, np.sin(t), np.cos(t)])
    np.savetxt(path, table, delimiter=',', header='time,y_field,u_coil', comments='')
    d = load_data(path)
    assert d.Ts == pytest.approx(0.002)
    assert d.output_names == ('y_field',) and d.input_names == ('u_coil',)
    d2 = load_data(path, outputs=['u_coil'], inputs=['y_field'], Ts=1.0)
    assert np.allclose(d2.y[:, 0], np.cos(t))


@pytest.mark.parametrize(
    ('content', 'kwargs', 'match'),
    [
        ({'DATA': np.zeros((3, 10))}, {'Ts': 1.0, 'rows': ([1], [9])}, 'row 9 out of range'),
        ({'DATA': np.zeros((3, 10))}, {'Ts': 1.0}, 'choose output and input rows'),
        ({'X': np.zeros((3, 10))}, {'Ts': 1.0, 'rows': ([1], [2])}, "no variable 'DATA'"),
        ({'y': np.zeros(10)}, {'Ts': 1.0}, "no variable 'u'"),
        ({'y': np.zeros(10), 'u': np.zeros(10)}, {}, 'stores no sample time'),
        ({'y': np.full(10, np.nan), 'u': np.zeros(10)}, {'Ts': 1.0}, 'y contains 10 NaN'),
    ],
)
def test_mat_errors(tmp_path, content, kwargs, match):
    path = tmp_path / 'bad.mat'
    savemat(path, content)
    with pytest.raises(DataFileError, match=match):
        load_data(path, **kwargs)


def test_missing_file_unknown_type_and_v73(tmp_path):
    with pytest.raises(DataFileError, match='does not exist'):
        load_data(tmp_path / 'nope.mat')
    (tmp_path / 'd.txt').write_text('1')
    with pytest.raises(DataFileError, match="unknown data file type '.txt'"):
        load_data(tmp_path / 'd.txt')
    header = b'MATLAB 7.3 MAT-file, HDF5 schema 1.00 .'.ljust(116) + bytes(8) + b'\x00\x02IM'
    (tmp_path / 'v73.mat').write_bytes(header + bytes(512))
    with pytest.raises(DataFileError, match=r"v7.3 .*save\('v73.mat', 'DATA', '-v7'\)"):
        load_data(tmp_path / 'v73.mat', Ts=1.0, rows=([1], [2]))


def test_csv_errors(tmp_path):
    path = tmp_path / 'd.csv'
    path.write_text('a,b\n1,2\n3,4\n')
    with pytest.raises(DataFileError, match='no output columns'):
        load_data(path, Ts=1.0)
    with pytest.raises(DataFileError, match="no column 'z'"):
        load_data(path, Ts=1.0, outputs=['z'])
