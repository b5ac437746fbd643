"""maglev-sysid reads what a data file says: names, units, time; and refuses what it cannot use.

Each test is one defect seen on real lab data: a constant input fitted as "ok",
a time vector with a dropout or running backwards accepted silently, names and
units of our own converter's .mat ignored, an unstable model "n/a" with --horizon.
"""

import json

import numpy as np
import pytest
from sysid.systems import lab_second_order

from maglev_ros.bags import write_dataset
from maglev_ros.cli.sysid import main
from maglev_ros.sysid import DataFileError, IdData, load_data


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope='module')
def lab():
    return lab_second_order(N=4000)


@pytest.mark.parametrize('detrend', [[], ['--detrend']])
def test_a_constant_input_is_named_and_refused(lab, tmp_path, capsys, detrend):
    path = tmp_path / 'constant.npz'
    np.savez(path, y=lab.y, u=np.full(lab.N, 2.0), Ts=lab.Ts)
    code, out, err = run([path, '--arx', 2, 2, 1, *detrend], capsys)
    assert code == 2 and out == '' and err.count('\n') == 1
    assert "input 'u1' (always 2) is constant" in err and 'excitation' in err


def csv_file(path, t, data):
    table = np.column_stack([t, data.y, data.u])
    np.savetxt(path, table, delimiter=',', header='t,Bx [T],Ix [A]', comments='', fmt='%.10g')
    return path


def test_a_time_gap_is_one_clear_error_or_cut_with_allow_gaps(lab, tmp_path, capsys):
    t = lab.time.copy()
    t[2500:] += 0.49  # a 0.49 s dropout
    path = csv_file(tmp_path / 'gap.csv', t, lab)
    code, out, err = run([path, '--outputs', 'Bx', '--inputs', 'Ix', '--oe', 2, 2, 1], capsys)
    assert code == 2 and err.count('\n') == 1
    assert '1 gap(s) (0.49 s at t = 0.4998 s' in err and '--allow-gaps' in err
    argv = [path, '--outputs', 'Bx', '--inputs', 'Ix', '--detrend', '--oe', 2, 2, 1]
    code, out, err = run([*argv, '--allow-gaps', '--json'], capsys)
    result = json.loads(out)
    assert result['data']['N'] == 2500 and code == result['exit_status'], err
    assert 'kept the longest gap-free piece, samples 1-2500 of 4000' in result['hints'][0]


def test_time_running_backwards_is_one_clear_error(lab, tmp_path, capsys):
    t = lab.time.copy()
    t[1000:] -= 0.05
    path = csv_file(tmp_path / 'back.csv', t, lab)
    code, _, err = run([path, '--outputs', 'Bx', '--inputs', 'Ix', '--arx', 2, 2, 1], capsys)
    assert code == 2 and err.count('\n') == 1
    assert 'time runs backwards or stands still at sample 1001' in err
    with pytest.raises(DataFileError, match='--allow-gaps'):  # gaps are refused by default
        load_data(
            csv_file(tmp_path / 'g.csv', np.r_[lab.time[:10], lab.time[10:] + 1], lab),
            outputs=['Bx'],
            inputs=['Ix'],
        )


def test_jitter_is_refused(lab, tmp_path):
    t = lab.time + np.where(np.arange(lab.N) % 7 == 3, 0.3 * lab.Ts, 0.0)
    with pytest.raises(DataFileError, match='the sampling is not uniform'):
        load_data(csv_file(tmp_path / 'j.csv', t, lab), outputs=['Bx'], inputs=['Ix'])


def test_names_units_and_time_of_our_own_mat_are_used(lab, tmp_path, capsys):
    data = IdData(lab.y, lab.u, lab.Ts, ['Bx_0'], ['ux'], ['T'], ['A'], t0=12.5)
    path = write_dataset(data, tmp_path / 'board.mat')
    loaded = load_data(path)  # no --rows needed: the file says which rows are what
    assert loaded.output_names == ('Bx_0',) and loaded.input_units == ('A',)
    assert loaded.output_units == ('T',) and loaded.t0 == pytest.approx(12.5)
    code, out, err = run([path, '--detrend', '--oe', 2, 2, 1, '--plot', tmp_path / 'png'], capsys)
    assert code == 0, err
    assert 'Channels (outputs, then inputs): Bx_0 [T], ux [A]' in out
    code, out, _ = run([path, '--detrend', '--oe', 2, 2, 1, '--json'], capsys)
    result = json.loads(out)
    assert result['data']['outputs'] == ['Bx_0'] and result['data']['output_units'] == ['T']
    assert result['data']['input_units'] == ['A']
    # the CSV converter output keeps units in its header, the npz in its arrays
    for suffix, names in (('csv', {'outputs': ['Bx_0'], 'inputs': ['ux']}), ('npz', {})):
        again = load_data(write_dataset(data, tmp_path / f'board.{suffix}'), **names)
        assert again.output_units == ('T',) and again.input_names == ('ux',)
        assert again.t0 == pytest.approx(12.5)


def test_an_unstable_model_gets_fits_with_horizon(tmp_path, capsys):
    rng = np.random.default_rng(2)
    u = rng.standard_normal(600)
    y = np.zeros(600)
    for t in range(1, 600):
        y[t] = 1.01 * y[t - 1] + u[t - 1] + 0.1 * rng.standard_normal()
    path = tmp_path / 'unstable.npz'
    np.savez(path, y=y, u=u, Ts=0.01)
    code, out, err = run([path, '--arx', 1, 1, 1, '--horizon', 1], capsys)
    assert code == 0, err
    summary = out[out.index('Summary') :]
    row = summary.splitlines()[2]
    assert 'n/a' not in row and 'unstable' in row, row
    code, out, _ = run([path, '--arx', 1, 1, 1, '--json', '--plot', tmp_path / 'p'], capsys)
    (model,) = json.loads(out)['models']
    assert model['status'] == 'unstable' and model['usable']
    assert model['fit_validation'] == [None] and model['kstep_validation'][0] > 90
    # --plot with only an unstable model still writes the k-step compare plot
    assert (tmp_path / 'p' / 'compare_kstep.png').is_file()
