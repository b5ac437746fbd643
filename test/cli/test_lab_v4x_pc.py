"""maglev-lab --firmware v4x_pc: what it refuses (one line, exit 2) before any work."""

from __future__ import annotations

import pytest

from maglev_ros.cli import lab


@pytest.mark.parametrize(
    ('argv', 'message'),
    [
        ([], '--firmware v4x_pc needs --board PATH or --virtual-board'),
        (['--virtual-board', '--magnet', 'fixed'], 'runs the closed loop: --magnet free'),
        (['--virtual-board', '--samples', '1'], '--samples must be >= 2, got 1'),
        (['--board', '/nonexistent/ttyACM9'], '--board /nonexistent/ttyACM9: no such device'),
        (['--board', '/dev/null', '--board-params', 'maggy_v4'], 'add --virtual-board'),
        (['--virtual-board', '--duration', '0'], 'argument --duration: must be positive'),
    ],
)
def test_bad_v4x_pc_sessions_give_one_line(argv, message, tmp_path, capsys):
    code = lab.main(['--firmware', 'v4x_pc', *argv, '--out', str(tmp_path / 'out')])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / 'out').exists()
