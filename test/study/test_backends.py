"""A study on a real Dask cluster (scheduler and two workers as processes) equals the local run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from waiting import wait_for

from maglev_ros.study import (
    DaskBackend,
    SerialBackend,
    load_study,
    plan_runs,
    run_study,
    run_task,
)

REPO = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).parent / 'dask'


def _env() -> dict:
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(REPO), env.get('PYTHONPATH', '')]).rstrip(os.pathsep)
    return env


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in reversed(procs):
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in reversed(procs):
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@pytest.fixture
def cluster(tmp_path):
    """A ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; yields the address."""
    file = tmp_path / 'scheduler.json'
    procs: list[subprocess.Popen] = []
    log = open(tmp_path / 'cluster.log', 'w')
    try:
        procs.append(
            subprocess.Popen(
                [
                    str(DASK),
                    'scheduler',
                    '--host',
                    '127.0.0.1',
                    '--port',
                    '0',
                    '--no-dashboard',
                    '--scheduler-file',
                    str(file),
                ],
                env=_env(),
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        )
        wait_for(lambda: file.exists() and file.stat().st_size > 0, 60, 'the scheduler file')
        wait_for(lambda: 'address' in json.loads(file.read_text() or '{}'), 10, 'its address')
        address = json.loads(file.read_text())['address']
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        str(DASK),
                        'worker',
                        address,
                        '--nthreads',
                        '1',
                        '--no-dashboard',
                        '--host',
                        '127.0.0.1',
                    ],
                    env=_env(),
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            )
        yield address
    finally:
        _stop(procs)
        log.close()


def test_cluster_table_equals_local_table(cluster, small_study, tmp_path):
    spec = load_study(small_study)
    with DaskBackend(cluster) as backend:
        backend.wait_for_workers(2, timeout=120)
        assert backend.workers == 2
        remote = run_study(spec, tmp_path / 'remote', backend)
    with DaskBackend(workers=2) as backend:
        local = run_study(spec, tmp_path / 'local', backend)
    assert remote.complete and local.complete and remote.total == 8
    assert remote.table.read_bytes() == local.table.read_bytes()
    assert json.dumps(remote.rows) == json.dumps(local.rows)  # NaN != NaN in ==
    # the runs differ from one another (seeds and draws), and both controllers ran
    assert len({r['seed'] for r in local.rows}) == 8
    assert {r['controller'] for r in local.rows} == {'lqr', 'pd'}
    assert {r['outcome'] for r in local.rows} >= {'ok', 'crashed'}


def test_an_unreachable_scheduler_is_one_clear_error():
    with pytest.raises(
        OSError, match=r'cannot reach the Dask scheduler tcp://127.0.0.1:9 .*dask scheduler'
    ):
        DaskBackend('tcp://127.0.0.1:9', timeout=2)


def test_serial_backend_rows_equal_a_direct_call(small_study, tmp_path):
    spec = load_study(small_study)
    tasks = plan_runs(spec)[:2]
    rows = list(SerialBackend().imap_unordered(run_task, tasks))
    assert json.dumps(rows) == json.dumps([run_task(t) for t in tasks])
