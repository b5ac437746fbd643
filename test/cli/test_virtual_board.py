import os
import signal
import subprocess
import sys
import time

import pytest
import serial

from maglev_ros.cli.virtual_board import load_plant, main
from maglev_ros.hardware.v2x_stream import RecordDecoder


@pytest.mark.parametrize(
    'argv, match',
    [
        (['--sensors', '0'], 'argument --sensors: must be >= 1, got 0'),
        (['--sensors', 'two'], "argument --sensors: expected an integer, got 'two'"),
        (['--firmware', 'v3x'], "argument --firmware: invalid choice: 'v3x'"),
        (['--clock-start', '-1'], 'must be in 0 .. 4294967295'),
        (['--startup-delay', 'nan'], 'must be finite and >= 0'),
        (['--plant', 'nosuchmodule_xyz:make'], "--plant 'nosuchmodule_xyz:make' cannot be loaded"),
        (['--plant', 'linearish'], "--plant must be 'linear', 'physics' or 'module:factory'"),
        (['--link', '/nonexistent-dir-xyz/tty'], 'link directory does not exist'),
        (['--firmware', 'v4x', '--log-period', '0'], '--log-period must be > 0'),
        (['--frobnicate'], 'unrecognized arguments: --frobnicate'),
    ],
)
def test_bad_input_exits_2_with_one_line(argv, match, capsys):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ''
    lines = captured.err.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith('maglev-virtual-board: error: ')
    assert match in lines[0]


def test_load_linear_plant():
    plant = load_plant('linear', 2)
    assert plant([0, 0, 0, 0], 0.0).shape == (2, 3)


def test_load_plant_from_a_factory(tmp_path, monkeypatch):
    (tmp_path / 'my_plants_xyz.py').write_text(
        'import numpy as np\n'
        'def make(n):\n'
        '    if n > 2:\n'
        '        raise ValueError("at most 2 sensors")\n'
        '    return lambda pwm, t: np.full((n, 3), 5.0)\n'
        'not_a_factory = 3\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert load_plant('my_plants_xyz:make', 2)([0, 0, 0, 0], 0.0).shape == (2, 3)
    assert main(['--plant', 'my_plants_xyz:make', '--sensors', '3']) == 2
    assert main(['--plant', 'my_plants_xyz:not_a_factory']) == 2


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
def test_runs_until_signal_and_cleans_up(signum, tmp_path):
    link = tmp_path / 'ttyMAGGY0'
    cmd = [sys.executable, '-m', 'maglev_ros.cli.virtual_board', '--startup-delay', '0.1']
    cmd += ['--sensors', '3', '--link', str(link)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == str(link)
        assert link.is_symlink()
        decoder = RecordDecoder(3)
        with serial.Serial(str(link), 9600, timeout=0.05) as port:
            deadline = time.monotonic() + 10.0
            while decoder.stats.records < 50:
                assert time.monotonic() < deadline
                decoder.feed(port.read(256))
        proc.send_signal(signum)
        assert proc.wait(timeout=10.0) == 0
        assert proc.stderr.read() == ''
        assert not os.path.lexists(link)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize(
    'argv, match',
    [
        (['--plant', 'physics', '--magnet', 'free', '--firmware', 'v4x'], '--magnet free needs'),
        (['--plant', 'physics', '--sensors', '2'], '--sensors must be 3'),
        (['--plant', 'physics', '--params', '/nonexistent/params.yaml'], '--params'),
        (['--plant', 'physics', '--supply-voltage', '0'], 'must be a positive finite number'),
        (['--plant', 'physics', '--noise', '-1e-4'], 'must be >= 0'),
        (['--plant', 'physics', '--quantization', 'lsb'], 'expected a number'),
        (['--plant', 'physics', '--sensor-delay', '-1'], 'must be >= 0'),
    ],
)
def test_physics_plant_arguments(argv, match, capsys):
    assert main(argv) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and match in lines[0]


def test_v4x_pc_board_sensor_must_exist(capsys):
    assert main(['--firmware', 'v4x_pc', '--board-sensor', '3']) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "--board-sensor must be below the plant's 3 sensors" in lines[0]


def test_v4x_pc_physics_board_answers_and_stops_on_signal(tmp_path):
    from maglev_ros.hardware.v4x_pc_link import V4xPcLink

    link = tmp_path / 'ttyMAGGY0'
    cmd = [sys.executable, '-m', 'maglev_ros.cli.virtual_board', '--firmware', 'v4x_pc']
    cmd += ['--magnet', 'fixed', '--link', str(link)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == str(link)
        with V4xPcLink(str(link), open_timeout=30.0) as board:  # set-up takes about 3.8 s
            board.command(85, 0)  # 1 A on x+, -1 A on x-
            currents = board.read_currents()
            assert currents[0] == pytest.approx(1.0, abs=0.01)
            assert currents[1] == pytest.approx(-1.0, abs=0.01)
            field, _ = board.read_sensors()
            # the magnet was absent at power-up: the board reports its field (tens of mT)
            assert 1.0 < abs(field[2]) < 200.0
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10.0) == 0
        assert proc.stderr.read() == ''
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
