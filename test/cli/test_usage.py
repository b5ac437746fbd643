"""The command-line conventions every maglev-* tool shares (maglev_ros.cli.usage)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from maglev_ros.cli.usage import Parser, UsageError, limit_blas_threads, run_command


def _parser():
    parser = Parser(prog='demo')
    parser.add_argument('--n', type=int, default=1)
    return parser


@pytest.mark.parametrize(
    'error', [ValueError('bad value 3\nsecond line'), OSError('no such file x'), UsageError('u')]
)
def test_domain_errors_are_one_line_and_status_2(error, capsys):
    def run(args):
        raise error

    assert run_command('demo', _parser(), run, []) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('demo: error: ')
    assert str(error).splitlines()[0] in err


def test_bad_arguments_are_one_line_and_status_2(capsys):
    assert run_command('demo', _parser(), lambda a: 0, ['--n', 'x']) == 2
    assert capsys.readouterr().err == "demo: error: argument --n: invalid int value: 'x'\n"


@pytest.mark.parametrize('error', [TypeError('bug'), KeyError('bug'), AttributeError('bug')])
def test_programming_errors_raise_with_their_traceback(error):
    def run(args):
        raise error

    with pytest.raises(type(error)):
        run_command('demo', _parser(), run, [])


def test_help_is_status_0(capsys):
    assert run_command('demo', _parser(), lambda a: 5, ['--help']) == 0
    assert 'usage: demo' in capsys.readouterr().out
    assert run_command('demo', _parser(), lambda a: 5, ['--n', '2']) == 5


def test_one_usage_error_class():
    from maglev_ros.cli import bag2data, lab, model, sysid, virtual_board

    for module in (bag2data, lab, model, sysid, virtual_board):
        assert getattr(module, 'UsageError', UsageError) is UsageError, module.__name__


def test_no_environment_change_at_import():
    code = (
        'import json, os; before = dict(os.environ); '
        'import maglev_ros.cli.lab, maglev_ros.cli.sysid, maglev_ros.cli.bag2data, '
        'maglev_ros.cli.model, maglev_ros.cli.virtual_board; '
        'print(json.dumps(sorted(set(os.environ.items()) ^ set(before.items()))))'
    )
    env = {
        k: v
        for k, v in __import__('os').environ.items()
        if k not in ('OPENBLAS_NUM_THREADS', 'ROS_AUTOMATIC_DISCOVERY_RANGE')
    }
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True, env=env
    )
    assert json.loads(out.stdout) == []


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='reads /proc/self/maps')
def test_blas_threads_are_limited_at_run_time():
    import numpy as np

    np.linalg.lstsq(np.eye(3), np.ones(3), rcond=None)  # OpenBLAS is loaded
    assert limit_blas_threads(1) >= 1
