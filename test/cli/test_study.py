"""``maglev-study``: bad study files, a run to the end, Ctrl-C and --resume (real processes)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from waiting import wait_for

from maglev_ros.cli.study import main
from maglev_ros.study import Journal, SerialBackend, load_study, read_table, run_study

REPO = Path(__file__).resolve().parents[2]

BASE = {'duration': 0.3, 'success': {'window': 0.1}, 'grid': {'x0.x': [0.0, 0.5e-3]}}


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / 'study.yaml'
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.mark.parametrize(
    ('change', 'key', 'problem'),
    [
        (
            {'grid': {'plant.polarisation': [0.0, 0.1]}},
            'grid.plant.polarisation',
            'unknown parameter',
        ),
        ({'fixed': {'sensor.noise': -1.0e-4}}, 'fixed.sensor.noise', 'must be >= 0'),
        ({'grid': {'sensor.noise': [1e-4, -1e-4]}}, 'grid.sensor.noise', 'must be >= 0'),
        ({'grid': {'x0.x': []}}, 'grid.x0.x', 'empty grid'),
        ({'grid': {'x0.x': {'start': 0, 'stop': 1e-3, 'num': 0}}}, 'grid.x0.x.num', 'empty grid'),
        (
            {'random': {'sensor.noise': {'normal': {'mean': 1e-4, 'std': -1e-5}}}},
            'random.sensor.noise.normal.std',
            'must be >= 0',
        ),
        (
            {'random': {'sensor.noise': {'normal': {'mean': 0.0, 'std': 1e-4}}}},
            'random.sensor.noise',
            'drew',
        ),
        ({'durations': 1.0}, 'durations', 'unknown key'),
        ({'grid': {'controller': ['lqr', 'pid']}}, 'grid.controller', 'expected one of lqr, pd'),
        (
            {'grid': {'controller.position_scale': [1e-4, 0.0]}},
            'grid.controller.position_scale',
            'position_scale must be a finite number > 0',
        ),
        ({'success': {'window': 0.5}}, 'success.window', 'longer than the duration'),
    ],
)
def test_a_bad_study_file_is_one_line_naming_the_key(tmp_path, capsys, change, key, problem):
    data = {**BASE, **change}
    path = _write(tmp_path, data)
    assert main([str(path), '--serial', '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f'maglev-study: error: {path}: {key}'), err[0]
    assert problem in err[0]
    assert not (tmp_path / 'out').exists()


def test_missing_file_and_used_out_dir_are_one_line(tmp_path, capsys):
    assert main([str(tmp_path / 'nope.yaml')]) == 2
    assert 'study file not found' in capsys.readouterr().err
    path = _write(tmp_path, {**BASE, 'fixed': {'controller': 'pd'}, 'grid': {'x0.x': [0.0]}})
    out = tmp_path / 'out'
    assert main([str(path), '--serial', '--out', str(out), '--no-plots', '--quiet']) == 0
    assert main([str(path), '--serial', '--out', str(out)]) == 2
    assert 'already holds a study: pass --resume' in capsys.readouterr().err
    other = _write(tmp_path, {**BASE, 'fixed': {'controller': 'pd'}, 'seed': 3})
    assert main([str(other), '--serial', '--out', str(out), '--resume']) == 2
    assert 'holds a different study' in capsys.readouterr().err


def test_list_shows_every_parameter(capsys):
    assert main(['--list']) == 0
    out = capsys.readouterr().out
    for key in ('plant.polarization', 'x0.x', 'loop.command_delay', 'controller.position_scale'):
        assert key in out


def test_sigint_keeps_the_finished_rows_and_resume_completes(tmp_path):
    data = {  # runs of about 1 s each: the SIGINT lands while the later ones still run
        'duration': 1.5,
        'seed': 4,
        'repeats': 3,
        'success': {'window': 0.1},
        'fixed': {'controller': 'pd'},
        'grid': {'x0.x': [0.0, 0.3e-3, 0.6e-3, 0.9e-3]},
    }
    path = _write(tmp_path, data)
    out = tmp_path / 'out'
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get('PYTHONPATH', '')])
    )
    cmd = [sys.executable, '-m', 'maglev_ros.cli.study', str(path), '--out', str(out), '--quiet']
    # its own process group, which gets the SIGINT, as Ctrl-C in a terminal sends it
    proc = subprocess.Popen(
        [*cmd, '--workers', '1'],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        journal = Journal(out / 'runs.jsonl')
        wait_for(lambda: len(journal.read()) >= 2, 180, 'two finished runs', period=0.05)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, stderr
    assert 'Traceback' not in stderr, stderr  # the workers ignore it: the study stops them
    kept = journal.read()
    assert 2 <= len(kept) < 12, 'interrupted too late: make the runs longer'
    assert 'continue with: maglev-study' in stderr and '--resume' in stderr
    partial = read_table(out / 'results.parquet')
    assert sorted(r['run'] for r in partial) == sorted(kept)
    resumed = subprocess.run(
        [*cmd, '--resume', '--serial', '--no-plots'],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert resumed.returncode == 0, resumed.stderr
    final = read_table(out / 'results.parquet')
    assert [r['run'] for r in final] == list(range(12))
    by_run = {r['run']: r for r in final}
    for index, row in kept.items():  # the kept rows are in the table as they were
        assert json.dumps(by_run[index]) == json.dumps(row)
    # and the whole table is the one an uninterrupted run gives
    straight = run_study(load_study(path), tmp_path / 'straight', SerialBackend())
    assert (out / 'results.parquet').read_bytes() == straight.table.read_bytes()
    assert '12 of 12 runs done' in resumed.stdout
