"""maglev-sysid --instruments: external instruments for --iv from data files."""

import json

import numpy as np
import pytest
from scipy.io import savemat
from sysid.closed_loop import THETA_CL, simulate_loop

from maglev_ros.cli.sysid import main


@pytest.fixture(scope='module')
def loop():
    return simulate_loop(20000, 0)


def iv_theta(argv, capsys):
    code = main([str(a) for a in argv] + ['--json'])
    result = json.loads(capsys.readouterr().out)
    assert code == result['exit_status'] and result['closed_loop'], result['feedback']
    models = result['models']
    for m in models:  # IV on the excitation is judged against it, and passes
        if m['structure'] == 'iv':
            assert m['status'] == 'ok' and 'instrument independence ok' in m['residuals_summary']
    return [np.array(m['theta']) for m in models]


def error(theta):
    return np.linalg.norm(theta - THETA_CL) / np.linalg.norm(THETA_CL)


def test_instruments_from_npz_mat_rows_and_csv(loop, tmp_path, capsys):
    data, r = loop
    npz = tmp_path / 'loop.npz'
    np.savez(npz, y=data.y, u=data.u, r=r, Ts=1.0)
    direct, external = iv_theta(
        [npz, '--arx', 2, 2, 1, '--iv', 2, 2, 1, '--instruments', 'r'], capsys
    )
    assert error(direct) > 0.25 and error(external) < 0.015
    mat = tmp_path / 'loop.mat'
    savemat(mat, {'DATA': np.vstack([data.y.T, data.u.T, r[None, :]])})
    (from_rows,) = iv_theta(
        [mat, '--rows', '1', '2', '--ts', 1, '--iv', 2, 2, 1, '--instruments', '3'], capsys
    )
    np.testing.assert_allclose(from_rows, external, rtol=1e-10)
    csv = tmp_path / 'loop.csv'
    np.savetxt(
        csv, np.column_stack([data.y, data.u, r]), delimiter=',', header='y,u,r', comments=''
    )
    (from_csv,) = iv_theta(
        [csv, '--inputs', 'u', '--ts', 1, '--iv', 2, 2, 1, '--instruments', 'r'], capsys
    )
    np.testing.assert_allclose(from_csv, external, rtol=1e-8)
    # without --instruments the same file gives the (biased) input-based iv4
    (plain,) = iv_theta([npz, '--iv', 2, 2, 1], capsys)
    assert error(plain) > 0.015


@pytest.mark.parametrize(
    ('extra', 'match'),
    [
        (['--arx', '2', '2', '1', '--instruments', 'r'], 'used by --iv only'),
        (['--iv', '2', '2', '1', '--instruments', 'w'], "has no variable 'w'"),
        (['--iv', '2', '2', '1', '--instruments', 'short'], 'expected (20000,)'),
    ],
)
def test_bad_instruments_exit_2(loop, tmp_path, capsys, extra, match):
    data, r = loop
    npz = tmp_path / 'loop.npz'
    np.savez(npz, y=data.y, u=data.u, r=r, short=r[:10], Ts=1.0)
    assert main([str(npz), *extra]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and match in lines[0], lines


def test_rows_instruments_must_be_rows(loop, tmp_path, capsys):
    data, r = loop
    mat = tmp_path / 'loop.mat'
    savemat(mat, {'DATA': np.vstack([data.y.T, data.u.T, r[None, :]])})
    argv = [str(mat), '--rows', '1', '2', '--ts', '1', '--iv', '2', '2', '1', '--instruments', 'r']
    assert main(argv) == 2
    assert 'takes rows of DATA counted from 1' in capsys.readouterr().err


def test_row_instruments_are_named_by_their_channel(loop, tmp_path, capsys):
    data, r = loop
    channels = np.vstack([data.y.T, data.u.T, r[None, :]])
    argv = ['--rows', '1', '2', '--ts', 1, '--iv', 2, 2, 1, '--instruments', '3']
    plain, named = tmp_path / 'plain.mat', tmp_path / 'named.mat'
    savemat(plain, {'DATA': channels})
    names = np.array(['x', 'i', 'reference'], dtype=object)
    savemat(named, {'DATA': channels, 'names': names, 'ny': 1, 'nu': 1})
    main([str(a) for a in [plain, *argv]])
    out = capsys.readouterr().out
    assert 'Instruments of --iv: DATA row 3\n' in out and 'u2' not in out
    main([str(a) for a in [named, *argv]])
    assert 'Instruments of --iv: reference\n' in capsys.readouterr().out
