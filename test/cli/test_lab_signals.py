"""maglev-lab as a user runs it: signals, an unfinished bag, a missing board (issue 11).

Each run is a real ``maglev-lab`` process in its own session and ROS domain.
"""

import os
import signal
import subprocess
import sys
import time

import pytest

from maglev_ros.bags import BagReader

START_TIMEOUT = 180.0  # s: a cold start compiles numba kernels


def lab_command(*args):
    return [sys.executable, '-m', 'maglev_ros.cli.lab', *map(str, args)]


def environment(domain):
    return dict(
        os.environ,
        ROS_DOMAIN_ID=str(domain),
        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
        PYTHONUNBUFFERED='1',
    )


def test_missing_board_fails_at_once_without_a_bag(domain, tmp_path):
    """Item 10: a board path that does not exist is one line, exit 2, no bag left."""
    out = tmp_path / 'lab'
    started = time.monotonic()
    proc = subprocess.run(
        lab_command('--board', '/dev/nonexistent', '--duration', 2, '--out', out),
        env=environment(domain), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert time.monotonic() - started < 30
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and '/dev/nonexistent' in lines[0], proc.stderr
    assert not (out / 'bag').exists()


def _mcap_size(bag):
    return sum(p.stat().st_size for p in bag.glob('*.mcap')) if bag.is_dir() else 0


@pytest.mark.parametrize('repeat', [False, True], ids=['once', 'repeated'])
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_signal_finalises_the_bag(domain, tmp_path, signum, repeat):
    """Item 8 / done-when 3: SIGINT, SIGTERM, SIGHUP (and more during clean-up)."""
    out = tmp_path / 'lab'
    bag = out / 'bag'
    proc = subprocess.Popen(
        lab_command('--duration', 3600, '--out', out, '--magnet', 'fixed', '--no-plots'),
        env=environment(domain), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while _mcap_size(bag) < 200_000:  # recording for a while: data in the file
            assert proc.poll() is None, proc.stdout.read()
            assert time.monotonic() < deadline, 'no data recorded'
            time.sleep(0.2)
        os.killpg(proc.pid, signum)
        while repeat and proc.poll() is None:
            time.sleep(0.003)
            try:
                os.killpg(proc.pid, signum)
            except ProcessLookupError:
                break
        output, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 128 + signum, output
    assert 'Traceback' not in output, output
    assert 'bag finalised' in output, output
    assert (bag / 'metadata.yaml').is_file(), sorted(bag.iterdir())
    with BagReader(bag) as reader:
        assert reader.topics['/maglev/currents'].count > 0


def test_overwrite_replaces_an_unfinished_bag(domain, tmp_path):
    """Item 8: --overwrite no longer refuses a bag without metadata.yaml."""
    out = tmp_path / 'lab'
    (out / 'bag').mkdir(parents=True)
    (out / 'bag' / 'bag_0.mcap').write_bytes(b'\x89MCAP0\r\n' + bytes(100))  # interrupted
    argv = ['--duration', 0.2, '--out', out, '--magnet', 'fixed', '--no-plots']
    proc = subprocess.run(
        lab_command(*argv), env=environment(domain), capture_output=True, text=True,
        timeout=START_TIMEOUT,
    )  # fmt: skip
    assert proc.returncode == 2 and 'add --overwrite' in proc.stderr, proc.stderr
    proc = subprocess.run(
        lab_command(*argv, '--overwrite'), env=environment(domain), capture_output=True,
        text=True, timeout=START_TIMEOUT,
    )  # fmt: skip
    # 0 or 1: the session's models (residual tests), not a refusal
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    assert 'wrote' in proc.stdout and (out / 'bag' / 'metadata.yaml').is_file()


def test_overwrite_keeps_a_directory_that_is_not_a_bag(tmp_path, capfd):
    from maglev_ros.cli import lab

    out = tmp_path / 'lab'
    (out / 'bag').mkdir(parents=True)
    (out / 'bag' / 'notes.txt').write_text('mine')
    assert lab.main(['--duration', '0.2', '--out', str(out), '--overwrite']) == 2
    assert 'is not a bag' in capfd.readouterr().err
    assert (out / 'bag' / 'notes.txt').is_file()


def test_signal_stops_the_closed_loop_session_and_finalises_the_bag(domain, tmp_path):
    """The main job's session stops on SIGINT between two reads: bag finalised, 130."""
    out = tmp_path / 'lab'
    bag = out / 'bag'
    proc = subprocess.Popen(
        lab_command('--samples', 300_000, '--settle', 0.1, '--out', out, '--no-plots'),
        env=environment(domain), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while _mcap_size(bag) < 200_000:  # recording for a while: data in the file
            assert proc.poll() is None, proc.stdout.read()
            assert time.monotonic() < deadline, 'no data recorded'
            time.sleep(0.2)
        os.killpg(proc.pid, signal.SIGINT)
        output, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 128 + signal.SIGINT, output
    assert 'Traceback' not in output and 'SIGINT: stopped; bag finalised' in output, output
    with BagReader(bag) as reader:
        counts = {t: i.count for t, i in reader.topics.items()}
        assert reader.metadata['session.stopped'] is True
    assert counts['/maglev/currents'] > 0 and len(set(counts.values())) == 1, counts
