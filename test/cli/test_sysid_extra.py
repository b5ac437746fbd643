"""maglev-sysid: NARX rows, confidence plots and covariance, reduction, several data files."""

import json

import numpy as np
import pytest
from sysid.systems import simulate_siso

from maglev_ros.cli.sysid import main


def npz(path, data):
    np.savez(path, y=data.y, u=data.u, Ts=data.Ts)
    return path


@pytest.fixture
def files(tmp_path):
    """Three experiments of the same ARX plant, and one of another plant with two inputs."""
    out = [npz(tmp_path / f'run{k}.npz', simulate_siso(3000, seed=k)) for k in range(3)]
    wide = simulate_siso(3000, seed=9)
    np.savez(tmp_path / 'wide.npz', y=wide.y, u=np.column_stack([wide.u, wide.u]), Ts=wide.Ts)
    return out, tmp_path / 'wide.npz'


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_several_files_print_a_fold_table(files, capsys):
    runs, _ = files
    code, out, err = run([*runs, '--arx', 2, 2, 1, '--armax', 2, 2, 1, 1, '--quiet'], capsys)
    assert code == 0, err
    assert '3 experiments as one data set' in out
    assert out.count('Validation k-fold over the files') == 2
    assert 'run1.npz, run2.npz' in out and out.count('mean ') == 2
    code, out, _ = run([*runs, '--arx', 2, 2, 1, '--kfold', 3, '--json'], capsys)
    summary = json.loads(out)
    folds = summary['models'][0]['folds']['folds']
    assert [f['validation'] for f in folds] == [['run0.npz'], ['run1.npz'], ['run2.npz']]
    assert np.array(summary['models'][0]['covariance']).shape == (4, 4)
    code, out, _ = run([*runs, '--narx', 2, 2, 1, 2, '--by-experiment', '--quiet'], capsys)
    assert code == 0 and 'by experiment' in out and 'NARX' in out


def test_narx_confidence_and_reduction_on_one_file(files, tmp_path, capsys):
    runs, _ = files
    plots = tmp_path / 'plots'
    argv = [runs[0], '--arx', 4, 4, 1, '--narx', 2, 2, 1, 2, '--reduce', '--confidence']
    code, out, err = run([*argv, '--plot', plots, '--quiet'], capsys)
    assert code == 0, err
    assert 'polynomial NARX' in out and 'u1(t-1)' in out and 'ERR' in out
    assert 'balanced truncation: order 4 ->' in out
    for name in ('bode_confidence', 'step_confidence', 'compare_narx', 'reduction_1_arx'):
        assert (plots / f'{name}.png').stat().st_size > 0
    code, out, _ = run([*argv, '--json'], capsys)
    summary = json.loads(out)
    arx_entry, narx_entry = summary['models']
    assert np.array(arx_entry['covariance']).shape == (8, 8)
    assert arx_entry['reduction']['order'] < 4
    assert narx_entry['structure'] == 'narx' and narx_entry['terms'][0]['names']


@pytest.mark.parametrize(
    ('extra', 'match'),
    [
        (['--kfold'], 'need several data files'),
        (['--narx', 2, 2, 1, 5], 'DEGREE from 1 to 4'),
        (['--reduce', 'x'], '--reduce takes a state count'),
        (['--confidence', '0'], '--confidence must be a positive'),
        (['{second}', '--kfold', 5], '--kfold K must be from 2 to 2'),
        (['{wide}'], 'the data files do not fit together'),
        (['{second}', '--reduce'], '--reduce and --confidence take one data file'),
    ],
)
def test_bad_input_exits_2_with_one_line(files, capsys, extra, match):
    runs, wide = files
    more = [{'{second}': runs[1], '{wide}': wide}[a] for a in extra if str(a).startswith('{')]
    options = [a for a in extra if not str(a).startswith('{')]
    code, out, err = run([runs[0], *more, '--arx', 2, 2, 1, *options], capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert match in lines[0]


def test_labels_are_the_shortest_distinct_tails(tmp_path):
    from maglev_ros.cli.sysid_extra import _labels

    assert _labels([tmp_path / 'a.npz', tmp_path / 'b.npz']) == ['a.npz', 'b.npz']
    bags = [tmp_path / 'lab1' / 'bag', tmp_path / 'lab2' / 'bag']
    assert _labels(bags) == ['lab1/bag', 'lab2/bag']


@pytest.fixture(scope='module')
def state_bag(tmp_path_factory):
    """The ROS-free closed loop (independent +-0.3 A PRBS per coil, 4 s) written as a bag."""
    from rclpy.serialization import serialize_message
    from sysid.physics_runs import record

    from maglev_ros.bags import BagWriter
    from maglev_ros.nodes.messages import currents_message, odometry_message

    result, _ = record('all', 0.3, 0.05, 20000, 0)
    path = tmp_path_factory.mktemp('sindy') / 'bag'
    t0, step = 1_700_000_000_000_000_000, 200_000
    with BagWriter(path) as bag:
        state = bag.add_topic('/maglev/state/true', 'nav_msgs/msg/Odometry')
        coils = bag.add_topic('/maglev/currents', 'sensor_msgs/msg/JointState')
        for k in range(len(result.x)):
            stamp = t0 + k * step
            bag.write(state, stamp, serialize_message(odometry_message(stamp, result.x[k])))
            bag.write(coils, stamp, serialize_message(currents_message(stamp, result.currents[k])))
    return path


def test_sindy_on_a_bag_prints_equations_and_the_physics_check(state_bag, capsys):
    pytest.importorskip('rclpy')
    code, out, err = run([state_bag, '--sindy'], capsys)
    assert code == 0, err
    assert 'd(vz)/dt = -17' in out and ' z^2' in out
    assert 'physics check ok: every mode within 10 %' in out
    code, out, _ = run([state_bag, '--sindy', '--sindy-threshold', '1e9', '--json'], capsys)
    summary = json.loads(out)  # nothing survives the threshold: the check fails, exit 1
    assert code == 1 and summary['exit_status'] == 1
    assert summary['eigenvalue_check'][0]['mode'] == 'unstable'


def test_sindy_needs_bags(files, capsys):
    runs, _ = files
    code, _, err = run([runs[0], '--sindy'], capsys)
    assert code == 2 and '--sindy reads states from bags' in err
