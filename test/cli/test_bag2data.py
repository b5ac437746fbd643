import json
import re

import numpy as np
import pytest
from bags.recordings import METADATA, SENSOR, TS, lockstep_data, write_lockstep_bag
from scipy.io import loadmat

from maglev_ros.cli.bag2data import main
from maglev_ros.sysid import load_data

OUT = [
    '--output',
    'bx=maglev/sensor_0/field:magnetic_field.x',
    '--output',
    'maglev/sensor_0/field:magnetic_field.z',
]
IN = [
    '--input',
    'ux=0.5*maglev/currents:effort[0]-0.5*maglev/currents:effort[1]',
    '--input',
    'maglev/currents/command:data[2]',
]


@pytest.fixture(scope='module')
def run():
    return lockstep_data(400, seed=5)


@pytest.fixture(scope='module')
def bag(tmp_path_factory, run):
    return str(write_lockstep_bag(tmp_path_factory.mktemp('cli') / 'run', run, 'sqlite3'))


def _expected(run):
    y = run.field[:, [0, 2]]
    u = np.column_stack([0.5 * run.currents[:, 0] - 0.5 * run.currents[:, 1], run.command[:, 2]])
    return y, u


def _error(capsys):
    err = capsys.readouterr().err
    assert err.count('\n') == 1, err
    assert err.startswith('maglev-bag2data: error: ')
    return err


def test_mat_file_has_the_lab_data_layout(bag, run, tmp_path, capsys):
    assert main([bag, *OUT, *IN, '--out', str(tmp_path / 'data.mat')]) == 0
    text = capsys.readouterr().out
    assert 'Ts 0.0002 s (5000 Hz), 400 samples' in text
    assert 'split     estimation 200 samples, validation 200 samples' in text
    assert 'metadata  params: maggy_v4' in text and 'gaps      none' in text
    mat = loadmat(tmp_path / 'data.mat')
    y, u = _expected(run)
    np.testing.assert_array_equal(mat['DATA'], np.vstack([y.T, u.T]))  # one channel per row
    assert mat['Ts'].item() == TS
    assert [str(n[0]) for n in mat['names'][0]] == [
        'bx',
        'maglev/sensor_0/field:magnetic_field.z',
        'ux',
        'maglev/currents/command:data[2]',
    ]
    est = loadmat(tmp_path / 'data_est.mat')['DATA']
    val = loadmat(tmp_path / 'data_val.mat')['DATA']
    np.testing.assert_array_equal(np.hstack([est, val]), mat['DATA'])
    back = load_data(tmp_path / 'data.mat', rows=([1, 2], [3, 4]))
    np.testing.assert_array_equal(back.y, y)
    assert back.Ts == TS


def test_npz_and_csv_load_back_exactly(bag, run, tmp_path, capsys):
    y, u = _expected(run)
    assert main([bag, *OUT, *IN, '--split', '100', '--out', str(tmp_path / 'd.npz')]) == 0
    data = load_data(tmp_path / 'd.npz')
    np.testing.assert_array_equal(data.y, y)
    np.testing.assert_array_equal(data.u, u)
    assert load_data(tmp_path / 'd_est.npz').N == 100
    assert main([bag, *OUT, *IN, '--out', str(tmp_path / 'd.csv')]) == 0
    names = ['bx', 'maglev/sensor_0/field:magnetic_field.z']
    data = load_data(
        tmp_path / 'd.csv', outputs=names, inputs=['ux', 'maglev/currents/command:data[2]']
    )
    np.testing.assert_array_equal(data.y, y)
    np.testing.assert_array_equal(data.u, u)
    assert data.Ts == pytest.approx(TS)


def test_json_summary_and_topic_listing(bag, capsys):
    assert main([bag, *OUT, *IN, '--json']) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary['samples'] == 400 and summary['Ts_s'] == TS
    assert summary['metadata'] == METADATA
    assert [c['unit'] for c in summary['channels']] == ['T', 'T', 'A', 'A']
    assert main([bag, '--topics', '--json']) == 0
    listing = json.loads(capsys.readouterr().out)
    assert {t['topic']: t['messages'] for t in listing['topics']}[SENSOR] == 400


@pytest.mark.parametrize(
    ('argv', 'message'),
    [
        (
            ['--output', 'maglev/sensor_9/field:magnetic_field.x'],
            r"no topic '/maglev/sensor_9/field'; its topics: /maglev/currents ",
        ),
        (['--output', 'maglev/sensor_0/field:magnetic_field.q'], r"has no field 'q'"),
        (['--output', 'maglev/sensor_0/field'], 'invalid channel spec'),
        ([], 'choose at least one --output'),
        (OUT + ['--split', '1.5'], r'argument --split: a split fraction must be in \(0, 1\)'),
        (OUT + ['--ts', '-1'], 'argument --ts: must be positive'),
        (OUT + ['--out', 'data.xlsx'], "unknown data file type '.xlsx'"),
        (OUT + ['--split', '400'], r'split index must be in 1\.\.399'),
    ],
)
def test_bad_input_exits_2_with_one_line(bag, capsys, argv, message):
    assert main([bag, *argv]) == 2
    assert re.search(message, _error(capsys))


def test_an_unwritable_output_fails_before_the_bag_is_read(bag, tmp_path, capsys):
    afile = tmp_path / 'afile'
    afile.write_text('not a directory\n')
    assert main([bag, *OUT, '--out', str(afile / 'data.mat')]) == 2
    assert f"--out {afile}/data.mat: '{afile}' is a file, not a directory" in _error(capsys)
    assert main([bag, *OUT, '--out', str(tmp_path / 'nodir' / 'data.mat')]) == 2
    assert f"directory '{tmp_path / 'nodir'}' does not exist: create it first" in _error(capsys)
    assert main([bag, *OUT, '--out', str(tmp_path)]) == 2
    assert 'is a directory: name a file' in _error(capsys)


def test_bad_bags_exit_2(tmp_path, capsys):
    assert main([str(tmp_path / 'none'), *OUT]) == 2
    assert 'does not exist' in _error(capsys)
    assert main([str(tmp_path), *OUT]) == 2
    assert 'is empty' in _error(capsys)


def test_gaps_exit_2_unless_allowed(tmp_path, run, capsys):
    bag = str(write_lockstep_bag(tmp_path / 'g', run, drop={SENSOR: [50]}))
    assert main([bag, *OUT]) == 2
    assert "gap in topic '/maglev/sensor_0/field': 1 missing sample" in _error(capsys)
    assert main([bag, *OUT, '--allow-gaps']) == 0
    assert '/maglev/sensor_0/field: 1 after t = 0.009800 s (linear)' in capsys.readouterr().out


def test_sysid_wiring(bag, run, tmp_path):
    # what maglev-sysid does with a bag argument: the same channel options, then IdData
    import argparse

    from maglev_ros.bags import is_bag_path, load_bag_dataset
    from maglev_ros.cli.bag2data import add_channel_arguments

    parser = argparse.ArgumentParser()
    parser.add_argument('data')
    parser.add_argument('--outputs')  # maglev-sysid's CSV option stays distinct
    add_channel_arguments(parser)
    args = parser.parse_args([bag, *OUT, *IN])
    assert is_bag_path(args.data) and not is_bag_path(tmp_path / 'data.mat')
    data = load_bag_dataset(
        args.data,
        outputs=args.output,
        inputs=args.input,
        Ts=None,
        allow_gaps=args.allow_gaps,
        tolerance=args.tolerance,
    )
    y, u = _expected(run)
    np.testing.assert_array_equal(data.y, y)
    np.testing.assert_array_equal(data.u, u)
    assert args.outputs is None


def test_a_truncated_finished_bag_is_rebuilt_with_force(tmp_path, run, capsys):
    bag = write_lockstep_bag(tmp_path / 'cut', run, 'mcap')
    storage = next(bag.glob('*.mcap'))
    storage.write_bytes(storage.read_bytes()[:-200])  # the summary at the end is lost
    assert main([str(bag), *OUT]) == 2
    assert 'truncated or corrupt (' in _error(capsys)
    assert main([str(bag), '--reindex']) == 2
    assert f'rebuild it anyway with maglev-bag2data --reindex --force {bag}' in _error(capsys)
    assert main([str(bag), *OUT, '--force']) == 2
    assert '--force goes with --reindex' in _error(capsys)
    assert main([str(bag), '--reindex', '--force']) == 0
    assert f'{bag}: rebuilt from {storage.name}.damaged (mcap): 1200 messages' in (
        capsys.readouterr().out
    )
    assert (bag / 'metadata.yaml.damaged').is_file()
    assert main([str(bag), *OUT, '--topics']) == 0
    listing = capsys.readouterr().out
    assert 'metadata  seed: 42' in listing and 'metadata  reindexed_from:' in listing


def test_a_plain_directory_is_not_called_a_bag(tmp_path, capsys):
    plain = tmp_path / 'plain'
    plain.mkdir()
    (plain / 'notes.txt').write_text('hello\n')
    assert main([str(plain), *OUT]) == 2
    assert f"'{plain}' is not a bag: it has neither metadata.yaml nor a .mcap" in _error(capsys)
    assert main([str(plain), '--reindex']) == 2
    assert f"'{plain}' is not a bag: it holds no .mcap or .db3 storage file" in _error(capsys)


@pytest.mark.parametrize('spelling', ['data', 'effort'])
def test_commands_of_either_type_convert_alike(bag, run, tmp_path, capsys, spelling):
    """A bag with JointState commands (stamped) gives the data of one with the older
    Float64MultiArray commands, whether the channel says data[i] or effort[i]."""
    joint = str(write_lockstep_bag(tmp_path / 'joint', run, stamped_commands=True))
    inputs = [IN[0], IN[1], IN[2], f'maglev/currents/command:{spelling}[2]']
    for path, out in ((bag, 'old.npz'), (joint, 'new.npz')):
        assert main([path, *OUT, *inputs, '--out', str(tmp_path / out)]) == 0
    capsys.readouterr()
    old, new = load_data(tmp_path / 'old.npz'), load_data(tmp_path / 'new.npz')
    _, u = _expected(run)
    np.testing.assert_array_equal(new.u, u)  # ux, and the command's current of coil 2
    np.testing.assert_array_equal(new.u, old.u)
    np.testing.assert_array_equal(new.y, old.y)
