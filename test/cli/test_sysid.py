import json
import warnings

import numpy as np
import pytest
from scipy.io import savemat
from sysid.systems import simulate_mimo_arx, simulate_siso

from maglev_ros.cli.sysid import main


@pytest.fixture
def lab_mat(tmp_path):
    """A data.mat like the lab's: DATA with one channel per row (y1, y2, spare, u1, u2)."""
    d = simulate_mimo_arx(6000, 1)
    DATA = np.vstack([d.y.T, np.zeros(d.N), d.u.T])
    path = tmp_path / 'data.mat'
    savemat(path, {'DATA': DATA})
    return path


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_siso_models_text(lab_mat, capsys):
    code, out, err = run(
        [
            lab_mat,
            '--rows',
            '2',
            '5',
            '--ts',
            '2e-4',
            '--detrend',
            '--arx',
            4,
            2,
            1,
            '--iv',
            4,
            2,
            1,
            '--armax',
            4,
            2,
            1,
            1,
            '--bj',
            2,
            1,
            4,
            4,
            1,
        ],
        capsys,
    )
    assert code == 0, err
    assert out.count('Discrete-time') == 4
    summary = out[out.index('Summary') :]
    assert '5-step val. %' in summary and 'residuals' in summary
    assert summary.count(' pass ') == 4 and 'no feedback detected' not in out
    assert 'estimation 3000, validation 3000' in out
    assert 'Fit to estimation data' in out and 'validation data' in out
    assert 'FPE:' in out and 'residual analysis' in out


def test_mimo_spec_json_plot_save(lab_mat, tmp_path, capsys):
    spec = tmp_path / 'spec.yaml'
    spec.write_text(
        'models:\n'
        '  - {structure: arx, na: [[4, 4], [0, 4]], nb: [[2, 2], [0, 2]],'
        ' nk: [[1, 1], [1, 1]]}\n'
        '  - {structure: armax, na: [[2, 2], [0, 2]], nb: [[1, 1], [0, 1]],'
        ' nc: [1, 1]}\n'
    )
    code, out, err = run(
        [
            lab_mat,
            '--rows',
            '1,2',
            '4,5',
            '--ts',
            '2e-4',
            '--spec',
            spec,
            '--json',
            '--plot',
            tmp_path / 'png',
            '--save',
            tmp_path / 'models',
            '--split',
            '4000',
        ],
        capsys,
    )
    # ARMAX with these orders cannot describe the ARX data: its residuals say so
    assert code == 1, err
    result = json.loads(out)
    assert result['data']['n_estimation'] == 4000
    arx_entry, armax_entry = result['models']
    assert arx_entry['status'] == 'ok' and arx_entry['residuals'] == 'pass'
    assert armax_entry['status'] == 'whiteness and independence failed'
    assert not armax_entry['usable'] and 'not white' in armax_entry['reason']
    assert result['closed_loop'] is False and result['kstep_horizon'] == 5
    assert len(arx_entry['kstep_validation']) == 2
    assert arx_entry['structure'] == 'arx' and armax_entry['structure'] == 'armax'
    assert arx_entry['orders']['na'] == [[4, 4], [0, 4]]
    assert min(arx_entry['fit_validation']) > 80
    assert len(arx_entry['polynomials']['A'][0][1]) == 5
    assert {'fpe', 'mse', 'fit_estimation', 'theta', 'std'} <= set(arx_entry)
    pngs = sorted(p.name for p in (tmp_path / 'png').iterdir())
    assert pngs == [
        'bode.png', 'compare.png', 'compare_kstep.png', 'resid_1_arx.png', 'resid_2_armax.png'
    ]  # fmt: skip
    assert len(list((tmp_path / 'models').iterdir())) == 2


def test_select_and_csv(tmp_path, capsys):
    d = simulate_siso(3000, 2)
    path = tmp_path / 'd.csv'
    np.savetxt(
        path, np.column_stack([d.time, d.y, d.u]), delimiter=',', header='t,y,u', comments=''
    )
    code, out, err = run(
        [path, '--select', 'mdl', '--select-max', 4, 4, 1, '--horizon', 5], capsys
    )
    assert code == 0, err
    assert 'Order search (mdl, 16 candidates): na=2 nb=2 nk=1' in out
    assert '5-step prediction' in out


@pytest.mark.parametrize(
    ('args', 'match'),
    [
        (['missing.mat', '--arx', 1, 1, 1, '--ts', 1], 'does not exist'),
        (['{mat}', '--rows', '1', '4', '--arx', 1, 1, 1], 'stores no sample time'),
        (['{mat}', '--rows', '1', '4', '--ts', '0', '--arx', 1, 1, 1], '--ts must be a positive'),
        (['{mat}', '--rows', '1', '4', '--ts', '-2', '--arx', 1, 1, 1], '--ts must be a positive'),
        (
            ['{mat}', '--rows', '1', '4', '--ts', 'inf', '--arx', 1, 1, 1],
            '--ts must be a positive sample time in seconds, a finite number, got inf',
        ),
        (['{mat}', '--rows', '1', '4', '--ts', 'nan', '--arx', 1, 1, 1], 'got nan'),
        (
            ['{mat}', '--matrix', 'X', '--rows', '1', '4', '--ts', '1', '--arx', 1, 1, 1],
            "no variable 'X'",
        ),
        (['{nan}', '--rows', '1', '2', '--ts', '1', '--arx', 1, 1, 1], 'NaN or infinite'),
        (
            ['{mat}', '--rows', '1', '4', '--ts', '1', '--arx', 40, 40, 1, '--split', '50'],
            'fewer samples than parameters',
        ),
        (
            ['{mat}', '--rows', '1,2', '4,5', '--ts', '1', '--spec', '{badspec}'],
            'na must be a scalar or have shape',
        ),
        (['{mat}', '--rows', '1', '4', '--ts', '1'], 'no model requested'),
        (
            ['{mat}', '--rows', '1', '4', '--ts', '1', '--arx', 1, 1, 1, '--split', 'half'],
            '--split must be a fraction',
        ),
        (['{mat}', '--rows', '1,2', '4,5', '--ts', '1', '--oe', 2, 2, 1], 'single-input'),
        (['{mat}', '--rows', '1', '4', '--ts', '1', '--arx', 1, 1], 'expected 3 arguments'),
        (['{mat}', '--rows', '1', '4', '--ts', '1', '--arx', 0, 0, 1], '--arx 0 0 1: na and nb'),
        (
            ['{mat}', '--rows', '1', '4', '--ts', '1e-3', '--filter', 0, 800, '--arx', 1, 1, 1],
            '--filter 0 800: the band is above the Nyquist frequency 500 Hz',
        ),
        (
            [
                '{mat}',
                '--rows',
                '1',
                '4',
                '--ts',
                '1e-3',
                '--filter',
                600,
                'inf',
                '--arx',
                1,
                1,
                1,
            ],
            '--filter 600 inf: the band is above the Nyquist frequency 500 Hz',
        ),
        (
            ['{mat}', '{mat}', '--rows', '1', '4', '--ts', '1e-3', '--filter', 0, 501]
            + ['--arx', 1, 1, 1],
            '--filter 0 501: the band is above the Nyquist frequency 500 Hz',
        ),
        (['{mat}', '--rows', '1', '4', '--ts', '1', '--iv', 0, 0, 2], '--iv 0 0 2: na and nb'),
        (['{mat}', '--rows', '1', '4', '--ts', '1', '--armax', 0, 0, 0, 1], 'nothing to estimate'),
        (['{mat}', '--rows', '1', '4', '--ts', '1', '--oe', 0, 2, 1], '--oe 0 2 1: nb is 0'),
        (['{mat}', '--rows', '1', '4', '--ts', '1', '--bj', 0, 1, 1, 1, 1], '--bj 0 1 1 1 1: nb'),
    ],
)
def test_bad_input_exits_2_with_one_line(lab_mat, tmp_path, capsys, args, match):
    nan = tmp_path / 'nan.mat'
    savemat(nan, {'DATA': np.array([[1.0, np.nan, 2.0], [0.0, 1.0, 2.0]])})
    badspec = tmp_path / 'bad.yaml'
    badspec.write_text('models:\n  - {structure: arx, na: [1, 2, 3], nb: 1, nk: 1}\n')
    argv = [str(a).format(mat=lab_mat, nan=nan, badspec=badspec) for a in args]
    code, out, err = run(argv, capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('maglev-sysid: error:')
    assert match in lines[0]
    assert 'Traceback' not in err


def test_help_exits_zero(capsys):
    assert main(['--help']) == 0
    assert 'usage: maglev-sysid' in capsys.readouterr().out


@pytest.fixture(scope='module')
def second_order_mat(tmp_path_factory):
    """The lab's data.mat from a lower-order board: DATA rows Bx, spare, spare, Ix."""
    from sysid.systems import lab_second_order

    d = lab_second_order()
    path = tmp_path_factory.mktemp('second_order') / 'data.mat'
    zeros = np.zeros(d.N)
    savemat(path, {'DATA': np.vstack([d.y[:, 0], zeros, zeros, d.u[:, 0]])})
    return path


def test_readme_siso_example_on_second_order_data_keeps_every_model(
    second_order_mat, tmp_path, capfd
):
    # the README's flagship command: IV 7 9 1 is unstable on 2nd-order data (pole 1.41);
    # it used to raise "SVD did not converge" (exit 2, ARX and ARMAX lost) with LAPACK
    # text on fd 1
    plots = tmp_path / 'plots' / 'x'
    argv = [second_order_mat, '--rows', '1', '4', '--ts', '2e-4', '--detrend']
    argv += ['--arx', 7, 9, 1, '--iv', 7, 9, 1, '--armax', 5, 5, 3, 1, '--plot', plots]
    code = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    # white sensor noise: ARX's residuals are not white; the reduced IV 7 9 1 leaves
    # input dynamics in its residuals; ARMAX describes the data
    assert code == 1, err
    assert 'DLASCL' not in out + err and 'illegal value' not in out + err
    summary = out[out.index('Summary') :]
    assert 'ARX 7 9 1' in summary and 'ARMAX 5 5 3 1' in summary
    assert 'IV4 7 9 1' in summary and 'validated without the' in out
    assert 'pole-zero pair(s) nearly cancel' in out
    assert 'whiteness failed - not usable' in summary
    names = sorted(p.name for p in plots.iterdir())
    assert names == [
        'bode.png',
        'compare.png',
        'compare_kstep.png',
        'resid_1_arx.png',
        'resid_2_iv.png',
        'resid_3_armax.png',
    ]


def test_json_is_clean_and_holds_the_reduced_model(second_order_mat, capfd):
    argv = [second_order_mat, '--rows', '1', '4', '--ts', '2e-4', '--detrend', '--json']
    argv += ['--arx', 2, 2, 1, '--iv', 7, 9, 1]
    code = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    result = json.loads(out)  # nothing but JSON on stdout
    assert code == 1, err
    arx_row, iv_row = result['models']
    assert arx_row['status'] == 'whiteness failed' and arx_row['fit_validation'][0] > 99
    assert arx_row['residuals'] == 'fail: whiteness' and not arx_row['usable']
    assert iv_row['validated']['orders']['na'][0][0] < 7
    assert iv_row['fit_validation'][0] > 99 and 'cancel' in iv_row['reason']
    assert iv_row['kstep_validation'][0] > 99 and iv_row['kstep_horizon'] == 5
    assert result['exit_status'] == 1 and result['hints'] == []
    assert result['closed_loop'] is False and result['warnings'] == []


def test_output_equal_to_input_is_one_line_and_no_lapack_text(second_order_mat, capfd):
    code = main(
        [str(second_order_mat), '--rows', '1', '1', '--ts', '2e-4', '--arx', '2', '2', '1']
    )
    out, err = capfd.readouterr()
    assert code == 2 and out == ''
    assert err.count('\n') == 1 and 'are the same signal' in err


def test_offset_hint_without_detrend_and_help_says_detrend_is_off(second_order_mat, capsys):
    code, out, err = run(
        [second_order_mat, '--rows', '1', '4', '--ts', '2e-4', '--oe', 2, 2, 1], capsys
    )
    # the offset the model cannot describe shows in its residuals: not usable
    assert code == 1, err
    assert 'independence failed - not usable' in out
    assert 'hint: y1 has an offset' in out and '--detrend' in out
    assert main(['--help']) == 0
    text = ' '.join(capsys.readouterr().out.split())
    assert 'off unless given' in text and 'Without --detrend the models fit the raw values' in text
    assert 'Exit status: 0 every model usable' in text and '1 some model not usable' in text


def test_iteration_cap_option_is_reported(second_order_mat, capsys):
    argv = [second_order_mat, '--rows', '1', '4', '--ts', '2e-4', '--detrend']
    code, out, err = run([*argv, '--armax', 2, 2, 2, 1, '--max-iter', 1], capsys)
    assert code in (0, 1), err
    assert 'Stopped at the iteration cap (1)' in out and 'raise it with --max-iter' in out
    code, _, err = run([*argv, '--armax', 2, 2, 2, 1, '--max-iter', 0], capsys)
    assert code == 2 and '--max-iter must be >= 1' in err


def test_negative_exponent_value_and_yaml_position(lab_mat, tmp_path, capsys):
    code, _, err = run([lab_mat, '--rows', '1', '4', '--ts', '-2e-4', '--arx', 1, 1, 1], capsys)
    assert code == 2 and '--ts must be a positive sample time' in err
    spec = tmp_path / 'broken.yaml'
    spec.write_text('models:\n  - structure: arx\n    na: [1, 2\n    nb: 1\n')
    code, _, err = run([lab_mat, '--rows', '1', '4', '--ts', '1', '--spec', spec], capsys)
    assert code == 2 and err.count('\n') == 1
    assert 'line 4, column' in err


@pytest.mark.parametrize(
    'name, content, match',
    [
        ('empty.mat', b'', 'empty.mat is empty'),
        ('empty.npz', b'', 'empty.npz is empty'),
        ('empty.csv', b'', 'empty.csv is empty'),
        ('header.csv', b'y,u\n', 'header line but no rows'),
        ('junk.npz', b'not a zip archive at all', 'not a readable .npz archive'),
        ('junk.mat', b'\x01\x02' * 100, 'not a readable MATLAB file'),
    ],
)
def test_empty_or_broken_data_file_is_one_line_and_no_warning(
    tmp_path, capsys, name, content, match
):
    path = tmp_path / name
    path.write_bytes(content)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        code, out, err = run([path, '--ts', '1e-3', '--arx', 2, 2, 1], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('maglev-sysid: error:')
    assert match in lines[0]


@pytest.mark.parametrize('option', ['--plot', '--save'])
def test_an_output_directory_that_is_a_file_fails_before_the_work(
    lab_mat, tmp_path, capsys, option
):
    afile = tmp_path / 'afile'
    afile.write_text('not a directory\n')
    argv = [lab_mat, '--rows', '1', '4', '--ts', '1', '--arx', 1, 1, 1]
    code, out, err = run([*argv, option, afile / 'sub'], capsys)
    assert code == 2 and 'Summary' not in out
    lines = err.strip().splitlines()
    assert len(lines) == 1
    assert f"{option} {afile}/sub: '{afile}' is a file, not a directory" in lines[0]
    code, out, err = run([*argv, option, afile], capsys)
    assert code == 2 and f'{option} {afile}: is a file, not a directory' in err
