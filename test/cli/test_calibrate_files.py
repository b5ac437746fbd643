"""``maglev-calibrate`` on data files (as maglev-sysid reads them) and a processed board."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest
from greybox.levitation import TRUTH, levitation_record, plant_parameters

from maglev_ros.bags import write_dataset
from maglev_ros.cli.calibrate import main
from maglev_ros.physics import MaggyModel
from maglev_ros.physics.board_processing import BoardProcessing
from maglev_ros.sysid import IdData

N = 6000
FREE = ['--free', 'magnet.mass', 'magnet.polarization']


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    exp, _ = levitation_record()
    board = BoardProcessing.from_model(MaggyModel(plant_parameters()))
    processed = board.apply(exp.y, exp.u, exp.Ts)
    names = [f'B{a}_{k}' for k in range(3) for a in 'xyz']
    root = tmp_path_factory.mktemp('files')
    out = {}
    for label, y in (('raw', exp.y), ('board', processed)):
        data = IdData(y[:N], exp.u[:N], exp.Ts, names, [f'i{j}' for j in range(4)])
        out[label] = write_dataset(replace(data, output_units=('T',) * 9), root / f'{label}.npz')
    out['mat'] = write_dataset(IdData(exp.y[:N], exp.u[:N], exp.Ts), root / 'unnamed.mat')
    return out


def estimates(text):
    found = {}
    for name in ('magnet.mass', 'magnet.polarization'):
        line = next(ln for ln in text.splitlines() if ln.strip().startswith(name))
        numbers = [float(v) for v in re.findall(r'-?\d+\.?\d*(?:e-?\d+)?', line.split(name)[1])]
        found[name] = numbers
    return found


def test_a_processed_board_with_the_board_model(files, tmp_path, capsys):
    out = tmp_path / 'board.yaml'
    argv = [f'{files["board"]}@free', *FREE, '--measurement', 'board', '--out', str(out)]
    status = main(argv)
    text = capsys.readouterr().out
    assert 'board field' in text and 'sits at its' not in text, text
    # mass and polarisation: each within 3 of its reported standard deviations
    for name, (_nominal, estimate, std, *_rest) in estimates(text).items():
        scale = 1e3 if name == 'magnet.mass' else 1.0  # the table shows g and T
        assert abs(estimate - scale * TRUTH[name]) <= 3 * std, (name, estimate, std)
    assert status == (0 if 'status: calibrated' in text else 1)


def test_the_wrong_measurement_model_is_refused_not_written(files, tmp_path, capsys):
    out = tmp_path / 'raw.yaml'
    status = main([f'{files["board"]}@free', *FREE, '--out', str(out)])
    text = capsys.readouterr().out
    assert status == 1 and 'status: not calibrated' in text and not out.exists()
    assert f'not written: {out}' in text and 'warning:' in text


def test_file_errors_are_one_line(files, capsys):
    assert main([str(files['board']), *FREE]) == 2
    assert '--magnet' in capsys.readouterr().err
    assert main([f'{files["mat"]}@free', *FREE, '--sensors', '0']) == 2
    err = capsys.readouterr().err
    assert "has no channel 'Bx_0'" in err and 'maglev-bag2data' in err
    assert (
        main([f'{files["board"]}@absent', '--free', 'coil0.gain', '--measurement', 'board']) == 2
    )
    assert '--measurement board is for levitation data' in capsys.readouterr().err
    assert main([f'{files["raw"]}@free', '--free', 'magnet.mass', '--split', '0.1']) == 2
    err = capsys.readouterr().err
    assert 'needs at least 1000 estimation samples' in err and '--split' in err


def test_a_board_feedthrough_without_the_board_model_is_one_line(files, capsys):
    board = f'{files["board"]}@free'
    assert main([board, *FREE, '--board-feedthrough', *['0'] * 6]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line.endswith('--board-feedthrough goes with --measurement board')
    assert main([board, *FREE, '--measurement', 'board', '--board-feedthrough', '1', '2']) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert '--board-feedthrough' in line and 'expected 6 arguments' in line
