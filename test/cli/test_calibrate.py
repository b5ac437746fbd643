"""``maglev-calibrate`` on simulated bags: the calibrated file, the plots, one-line errors."""

from __future__ import annotations

import pytest
from greybox.plant import write_bag

from maglev_ros.cli.calibrate import main
from maglev_ros.physics import load_parameters


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp('bags')
    return {
        'absent': write_bag(root / 'absent', 'absent', 5000),
        'fixed': write_bag(root / 'fixed', 'fixed', 5000),
        'unlabelled': write_bag(root / 'unlabelled', None, 1500),
    }


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_calibrates_and_writes_a_loadable_file(bags, tmp_path, capsys):
    out = tmp_path / 'myboard.yaml'
    status = main(
        [
            str(bags['absent']),
            str(bags['fixed']),
            '--params',
            'maggy_v2',
            '--free',
            'coil*.gain',
            'sensor1.x',
            'magnet.polarization',
            'magnet.mass',
            '--out',
            str(out),
        ]
    )
    text = capsys.readouterr().out
    # the fixed magnet's polarisation and tilt end at their bounds: said so, nothing written
    assert status == 1
    assert 'iteration 1:' in text  # progress
    assert 'magnet.mass: not identifiable' in text
    assert 'warning: magnet.polarization = -0.7 T sits at its upper bound' in text
    assert 'status: partly calibrated' in text and f'not written: {out}' in text
    assert not out.exists()
    status = main(
        [str(bags['absent']), '--free', 'coil*.gain', 'sensor1.x', '--out', str(out), '--plot',
         str(tmp_path / 'myboard.png')]
    )  # fmt: skip
    text = capsys.readouterr().out
    assert status == 0 and 'status: calibrated' in text
    params = load_parameters(out)
    assert params.name == 'myboard'
    # coil 0 gain, +3 % (the plant differs in more parameters than are free here: 2 %)
    assert 0.98 < params.solenoids.turns[0] / 480 / 1.03 < 1.02
    assert (tmp_path / 'myboard_0_absent.png').stat().st_size > 10_000
    assert (tmp_path / 'myboard_1_fixed.png').stat().st_size > 10_000
    assert (tmp_path / 'myboard.png').stat().st_size > 10_000
    assert out.read_text().startswith('# Calibrated by maglev-calibrate')


def test_unlabelled_bag_takes_the_magnet_from_the_command_line(bags, tmp_path, capsys):
    assert main([str(bags['unlabelled']), '--free', 'coil0.gain']) == 2
    assert '--magnet' in _error(capsys)
    status = main([f'{bags["unlabelled"]}@absent', '--free', 'coil0.gain', '--delay', '1'])
    assert status == 0


@pytest.mark.parametrize(
    ('args', 'expected'),
    [
        (['--free', 'coil7.gain'], "no parameter matches 'coil7.gain'"),
        (['--free', 'coil0.gain', '--bounds', 'coil0.gain=1.1:1.3'], 'exclude its nominal'),
        (['--free', 'coil0.gain', '--bounds', 'nope=0:1'], "unknown parameter 'nope'"),
        (
            ['--free', 'coil0.gain', '--output', 'maglev/sensor_5/field:magnetic_field.x'],
            "has no topic '/maglev/sensor_5/field'",
        ),
        (['--free', 'coil0.gain', '--params', 'maggy_v9'], 'maggy_v9'),
        ([], '--free'),
    ],
)
def test_bad_input_one_line_status_2(bags, capsys, args, expected):
    assert main([str(bags['absent']), *args]) == 2
    assert expected in _error(capsys)


def test_a_bag_without_the_topics(tmp_path, capsys):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from maglev_ros.bags import BagWriter

    with BagWriter(tmp_path / 'other', storage='mcap', metadata={'magnet': 'absent'}) as bag:
        chatter = bag.add_topic('/chatter', 'std_msgs/msg/String')
        for k in range(10):
            bag.write(chatter, 1_000_000 * (k + 1), serialize_message(String(data='hi')))
    assert main([str(tmp_path / 'other'), '--free', 'coil0.gain']) == 2
    assert 'no field topic of sensors 0 to 2 (/maglev/sensor_0/field, ...)' in _error(capsys)


def test_list(capsys):
    assert main(['--list']) == 0
    assert 'sensor2.offset_z' in capsys.readouterr().out


def test_a_subset_of_the_sensors(bags, capsys):
    status = main(
        [str(bags['absent']), '--sensors', '1', '2', '--free', 'coil0.gain', 'sensor0.x']
    )
    out = capsys.readouterr().out
    assert status == 0
    assert 'sensors 1, 2' in out
    assert 'sensor0.x: not identifiable, these data do not depend on it' in out
    assert main([str(bags['absent']), '--sensors', '3', '--free', 'coil0.gain']) == 2
    assert 'has sensors 0 to 2' in _error(capsys)


def test_magnet_from_the_recorder_metadata(tmp_path, capsys):
    # the recorder stores the simulator's parameters as '<node>.<parameter>'
    bag = write_bag(tmp_path / 'lab', 'absent', 1500, key='maglev_simulator.magnet')
    assert main([str(bag), '--free', 'coil0.gain']) == 0
    assert 'magnet absent' in capsys.readouterr().out


def test_dynamic_mode_from_a_levitation_bag(tmp_path, capsys):
    """The ROS-free loop's levitation record (1.2 s) as the recorder writes it, end to end."""
    from greybox.levitation import TRUTH, levitation_record
    from greybox.plant import write_record

    exp, _ = levitation_record()
    n = 6000
    # the recorder's metadata: its own keys, and the simulator's parameters as
    # '<node>.<parameter>' (maglev_simulator's magnet: free while levitating)
    metadata = {
        'recorder.storage': 'mcap',
        'recorder.topics': '/maglev/sensor_0/field /maglev/sensor_1/field '
        '/maglev/sensor_2/field /maglev/currents',
        'maglev_simulator.params': 'maggy_v2',
        'maglev_simulator.magnet': 'free',
    }
    bag = write_record(tmp_path / 'levitating', exp.u[:n], exp.y[:n], metadata)
    out = tmp_path / 'dynamic.yaml'
    status = main([str(bag), '--free', 'magnet.mass', 'magnet.polarization', '--out', str(out)])
    text = capsys.readouterr().out
    assert status == 0, text
    assert 'magnet levitating' in text  # from the metadata
    assert 'sensor delay 1 sample(s)' in text  # found, not given
    assert 'dynamic calibration' in text and 'iteration 1:' in text
    params = load_parameters(out)
    assert abs(params.magnet.mass / TRUTH['magnet.mass'] - 1) < 0.01
    assert abs(params.magnet.polarization / TRUTH['magnet.polarization'] - 1) < 0.01
    assert (tmp_path / 'dynamic.png').stat().st_size > 10_000
    # the full nonlinear model's predictor on the same bag
    out = tmp_path / 'nonlinear.yaml'
    free = ['magnet.mass', 'magnet.polarization']
    assert main([str(bag), '--free', *free, '--form', 'nonlinear', '--out', str(out)]) == 0
    assert 'nonlinear grey-box' in capsys.readouterr().out
    params = load_parameters(out)
    assert abs(params.magnet.mass / TRUTH['magnet.mass'] - 1) < 0.01
    assert abs(params.magnet.polarization / TRUTH['magnet.polarization'] - 1) < 0.01
    assert 'nonlinear grey-box' in out.read_text().splitlines()[2]
    assert main([str(bag), '--free', *free, '--form', 'quadratic']) == 2
    assert "--form: invalid choice: 'quadratic'" in _error(capsys)
    # a levitation bag with a static one: one clear line
    static = write_bag(tmp_path / 'absent', 'absent', 1500)
    assert main([str(bag), str(static), '--free', 'magnet.mass']) == 2
    assert 'separate runs' in _error(capsys)


@pytest.mark.parametrize(
    ('option', 'expected'),
    [
        ('--out', "--out {afile}/c.yaml: '{afile}' is a file, not a directory"),
        ('--plot', "--plot {afile}/c.png: '{afile}' is a file, not a directory"),
    ],
)
def test_an_output_path_that_cannot_be_written_fails_before_the_fit(
    bags, tmp_path, capsys, option, expected
):
    afile = tmp_path / 'afile'
    afile.write_text('not a directory\n')
    target = afile / ('c.yaml' if option == '--out' else 'c.png')
    argv = [str(bags['absent']), '--free', 'coil0.gain', option, str(target)]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert 'iteration' not in captured.out  # refused before the fit started
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and expected.format(afile=afile) in err[0]
