"""The first run's kernel compile: the progress line, and a stop signal during it."""

import io
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numba
import pytest

from maglev_ros.compile_watch import PROGRESS_TEXT, CompileWatch, compile_estimate

ROOT = Path(__file__).resolve().parents[1]
LINE_TIMEOUT = 300.0  # s until the compile starts: imports and rclpy, on a shared machine


def test_one_progress_line_when_kernels_compile():
    @numba.njit
    def twice(x):
        return 2.0 * x

    @numba.njit
    def thrice(x):
        return 3.0 * x

    out = io.StringIO()
    with CompileWatch('maglev-test', 12, stream=out) as watch:
        assert twice(1.0) == 2.0 and thrice(1.0) == 3.0
        assert twice(2.0) == 4.0  # compiled: no event
    assert out.getvalue() == f'maglev-test: {PROGRESS_TEXT}: ~12 s (cache: none)\n'
    assert watch.compiles == 2 and not watch.compiling and not watch.interrupted


def test_no_line_when_nothing_compiles():
    @numba.njit
    def once(x):
        return x + 1.0

    once(1.0)
    out = io.StringIO()
    with CompileWatch('maglev-test', 12, stream=out) as watch:
        assert once(1.0) == 2.0
    assert out.getvalue() == '' and watch.compiles == 0


def test_no_compile_starts_after_a_stop_signal():
    from waiting import wait_for

    from maglev_ros.compile_watch import CompileInterrupted
    from maglev_ros.stop_signals import StopSignals

    @numba.njit
    def later(x):
        return x - 1.0

    out = io.StringIO()
    with StopSignals([signal.SIGHUP]) as stop, CompileWatch('maglev-test', 1, stream=out) as watch:
        os.kill(os.getpid(), signal.SIGHUP)  # between compiles: nothing to interrupt yet
        wait_for(lambda: watch.stop_signal == signal.SIGHUP, what='the watcher')
        with pytest.raises(CompileInterrupted, match='during the kernel compile'):
            later(1.0)
    assert stop.requested and watch.interrupted and out.getvalue() == ''


def test_the_estimate_is_the_main_jobs_for_the_lab_and_grows_with_the_load(monkeypatch):
    monkeypatch.setattr(os, 'cpu_count', lambda: 2)
    monkeypatch.setattr(os, 'getloadavg', lambda: (0.5, 0.5, 0.5))
    idle = compile_estimate('maglev-lab')
    assert idle > compile_estimate('maglev_simulator') > 0
    monkeypatch.setattr(os, 'getloadavg', lambda: (12.0, 12.0, 12.0))
    assert compile_estimate('maglev-lab') == pytest.approx(6 * idle)


def _start_compiling(cmd, tmp_path, domain):
    """Start ``cmd`` with an empty numba cache; return it once it says it compiles."""
    env = dict(
        os.environ,
        NUMBA_CACHE_DIR=str(tmp_path / 'numba'),
        PYTHONPATH=str(ROOT),
        ROS_DOMAIN_ID=str(domain),
    )
    child = subprocess.Popen(
        cmd, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    lines = []
    deadline = time.monotonic() + LINE_TIMEOUT
    for line in child.stderr:  # the line, not a time: the compile has begun
        lines.append(line)
        if PROGRESS_TEXT in line or time.monotonic() > deadline:
            break
    if PROGRESS_TEXT not in ''.join(lines):
        child.kill()
        child.wait()
        pytest.fail(f'no progress line; stderr: {"".join(lines)[-2000:]}')
    return child, lines[-1]


def _stopped_within(child, seconds):
    start = time.monotonic()
    child.send_signal(signal.SIGINT)
    try:
        child.wait(timeout=30.0)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    rest = child.stderr.read()
    child.stderr.close()
    return time.monotonic() - start, rest


def test_a_node_stops_within_2_s_of_sigint_during_its_compile(tmp_path, domain):
    cmd = [sys.executable, '-m', 'maglev_ros.nodes.simulator']
    child, line = _start_compiling(cmd, tmp_path, domain)
    assert line.startswith(f'maglev_simulator: {PROGRESS_TEXT}: ~') and str(tmp_path) in line
    took, rest = _stopped_within(child, 2.0)
    assert took < 2.0, rest
    assert child.returncode == 0, rest  # a stop, not a failure (the bag of a launch is kept)


def test_a_command_stops_within_2_s_of_sigint_during_its_compile(tmp_path, domain):
    cmd = [sys.executable, '-m', 'maglev_ros.cli.model', 'simulate', '--duration', '0.01']
    child, line = _start_compiling(cmd, tmp_path, domain)
    assert line.startswith(f'maglev-model: {PROGRESS_TEXT}: ~')
    took, rest = _stopped_within(child, 2.0)
    assert took < 2.0, rest
    assert child.returncode == 130, rest
    assert 'interrupted' in rest or 'stopped during the kernel compile' in rest
