"""Fixtures of the tests that drive the package through the real ``ros2`` command line.

The package is built once per session with colcon (``colcon_build`` of
``test/conftest.py``); every test gets its own ROS domain and runs ``ros2``
(``ros2 run``, ``ros2 launch``, ``ros2 param`` ...) as a user would after
``source install/setup.bash``:

- ``ros2_cli`` (session): where ``ros2`` is and what it runs on; skips the test,
  with the reason, where ``ros2`` is not installed (``bash
  ../shared/ros2-cli/install.sh .venv`` installs it on top of the PyPI wheels).
- ``domain``: a ``ROS_DOMAIN_ID`` no other test of the session uses.
- ``ros2_env`` (session): a :class:`Ros2Env`: the environment as ``source
  install/setup.bash`` leaves it (``AMENT_PREFIX_PATH=<install>:<venv>``, the
  install tree's site-packages on ``PYTHONPATH``, unbuffered and uncoloured
  output); ``ros2_env.run(args, domain)`` and ``ros2_env.start(args, domain)``
  add the domain id and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; with
  :func:`interrupt` (Ctrl-C to the group) and :func:`wait_until`.
- ``ros2``: a :class:`Ros2` runner for one test, in its own domain, logs in the
  test's temporary directory. ``ros2.run(*args)`` runs ``ros2 <args>`` to the
  end; ``ros2.start(*args)`` starts it in its own session (process group) as a
  terminal's foreground job, output to a file, and the returned
  :class:`Ros2Process` sends signals to the whole group
  (:meth:`Ros2Process.interrupt_like_terminal`). Every process a test started
  is killed (group-wide) at the end of the test if it is still running.

Without the daemon: ``ros2 node/param/topic/service`` verbs take
``--no-daemon --spin-time 1`` (retried until the node is found), so that no ``ros2 daemon``
outlives a test.
"""

from __future__ import annotations

import itertools
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from conftest import SAFE_DOMAIN_IDS

# Domain ids whose DDS ports stay out of Linux's ephemeral range (test/conftest.py's
# ids), started half-way round from the node tests' counter so that the two
# sequences of one session do not meet for ~60 tests each.
_NEXT = itertools.count((os.getpid() + len(SAFE_DOMAIN_IDS) // 2) % len(SAFE_DOMAIN_IDS))

RUN_TIMEOUT = 120.0  # s, for a ros2 command that should end by itself
STOP_TIMEOUT = 30.0  # s, for a started ros2 command to end after a signal
_LAUNCH_EXIT = re.compile(
    r'^\[(?:INFO|ERROR)\] \[(?P<proc>[\w.-]+)-\d+\]: process '
    r'(?:has finished cleanly \[pid \d+\]|has died \[pid \d+, exit code (?P<code>-?\d+))',
    re.MULTILINE,
)
_LAUNCH_START = re.compile(
    r'^\[INFO\] \[(?P<proc>[\w.-]+)-\d+\]: process started with pid', re.MULTILINE
)


def _next_domain_id() -> int:
    return SAFE_DOMAIN_IDS[next(_NEXT) % len(SAFE_DOMAIN_IDS)]


@dataclass(frozen=True)
class Ros2Cli:
    """The ``ros2`` command line and the package install it runs.

    Attributes
    ----------
    executable : Path
        The ``ros2`` script.
    prefix : Path
        The colcon install prefix of maglev_ros.
    site_packages : Path
        Its Python directory.
    venv : Path
        The Python environment with rclpy (and the ament index of the wheels).
    """

    executable: Path
    prefix: Path
    site_packages: Path
    venv: Path


@pytest.fixture(scope='session')
def ros2_cli(colcon_build) -> Ros2Cli:
    """The real ``ros2`` command line over a colcon build (skips where absent)."""
    beside = Path(sys.executable).parent / 'ros2'
    found = beside if beside.is_file() else shutil.which('ros2')
    if found is None:
        pytest.skip(
            'ros2 is not installed: bash ../shared/ros2-cli/install.sh .venv installs the '
            'ROS 2 command line into the venv (or source a ROS 2 Jazzy install)'
        )
    colcon_build.require()
    return Ros2Cli(
        executable=Path(found),
        prefix=colcon_build.prefix,
        site_packages=colcon_build.site_packages(),
        venv=Path(sys.prefix),
    )


def _environment(cli: Ros2Cli) -> dict[str, str]:
    env = os.environ.copy()
    join = os.pathsep.join
    env['AMENT_PREFIX_PATH'] = join(
        filter(None, [str(cli.prefix), str(cli.venv), env.get('AMENT_PREFIX_PATH')])
    )
    env['PYTHONPATH'] = join(filter(None, [str(cli.site_packages), env.get('PYTHONPATH')]))
    env['PATH'] = join([str(cli.executable.parent), env.get('PATH', '')])
    env['PYTHONNOUSERSITE'] = '1'
    env['PYTHONUNBUFFERED'] = '1'
    env['RCUTILS_COLORIZED_OUTPUT'] = '0'
    env.pop('ROS_LOCALHOST_ONLY', None)
    return env


def _in_domain(env: dict[str, str], domain: int) -> dict[str, str]:
    return env | {'ROS_DOMAIN_ID': str(domain), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}


@dataclass(frozen=True)
class Ros2Env:
    """A colcon install of the package and the environment to run ``ros2`` in it.

    Attributes
    ----------
    cli : Ros2Cli
        The command line and the install.
    env : dict
        Environment as ``source install/setup.bash`` would leave it (domain
        id and discovery range set per call by :meth:`run`/:meth:`start`).
    """

    cli: Ros2Cli
    env: dict

    @property
    def prefix(self) -> Path:
        return self.cli.prefix

    def run(
        self, args: Sequence[str], domain: int, timeout: float = 60.0
    ) -> subprocess.CompletedProcess:
        """Run ``ros2 args...`` to completion (stdout and stderr captured as text)."""
        return subprocess.run(
            [str(self.cli.executable), *args],
            env=_in_domain(self.env, domain),
            capture_output=True,
            text=True,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
        )

    def start(self, args: Sequence[str], domain: int) -> subprocess.Popen:
        """Start ``ros2 args...`` in its own session (output merged into stdout)."""
        return subprocess.Popen(
            [str(self.cli.executable), *args],
            env=_in_domain(self.env, domain),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        )


def interrupt(proc: subprocess.Popen, timeout: float = STOP_TIMEOUT) -> tuple[int, str]:
    """Send SIGINT to the process group, as a terminal's Ctrl-C; return (status, output)."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        return -9, out
    return proc.returncode, out


@pytest.fixture(scope='session')
def ros2_env(ros2_cli: Ros2Cli) -> Ros2Env:
    """The install's ``ros2`` environment (skips where ``ros2`` or colcon is missing)."""
    return Ros2Env(ros2_cli, _environment(ros2_cli))


@pytest.fixture
def domain() -> int:
    """A ROS domain id of its own for one test."""
    return _next_domain_id()


@dataclass
class Ros2Process:
    """A command started in its own session, as a terminal's foreground job.

    Attributes
    ----------
    args : list of str
        The command line.
    popen : subprocess.Popen
        The process (the group leader: its pid is the process group id).
    log : Path
        Its standard output and error, interleaved.
    """

    args: list[str]
    popen: subprocess.Popen
    log: Path
    _closed: bool = field(default=False, repr=False)

    @property
    def pid(self) -> int:
        return self.popen.pid

    def output(self) -> str:
        """Everything the command wrote so far (stdout and stderr)."""
        return self.log.read_text(errors='replace') if self.log.is_file() else ''

    def wait_for(self, pattern: str, timeout: float) -> re.Match:
        """Wait until ``pattern`` (a regex) appears in the output; fail on timeout or exit."""
        regex = re.compile(pattern, re.MULTILINE)
        deadline = time.monotonic() + timeout
        while True:
            found = regex.search(self.output())
            if found:
                return found
            if self.popen.poll() is not None:
                pytest.fail(
                    f'{self.args} exited with {self.popen.returncode} before printing '
                    f'{pattern!r}:\n{self.output()[-6000:]}'
                )
            if time.monotonic() > deadline:
                pytest.fail(
                    f'{self.args}: no {pattern!r} after {timeout} s:\n{self.output()[-6000:]}'
                )
            time.sleep(0.1)

    def signal_group(self, signum: int = signal.SIGINT) -> None:
        """Send ``signum`` to the whole process group (no-op once it has ended)."""
        try:
            os.killpg(self.popen.pid, signum)
        except ProcessLookupError:
            pass

    def interrupt_like_terminal(self) -> None:
        """Ctrl-C in a terminal: SIGINT to every process of the group."""
        self.signal_group(signal.SIGINT)

    def wait(self, timeout: float = STOP_TIMEOUT) -> int:
        """Wait for the group leader to exit and return its status (fails on timeout)."""
        try:
            return self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(
                f'{self.args} still running {timeout} s after the signal '
                f'(killed):\n{self.output()[-6000:]}'
            )

    def group_alive(self) -> bool:
        """True while any process of the group still exists."""
        try:
            os.killpg(self.popen.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # pragma: no cover - a zombie group member
            return True
        return True

    def wait_group(self, timeout: float = STOP_TIMEOUT) -> bool:
        """Wait until no process of the group is left; True if none is."""
        deadline = time.monotonic() + timeout
        while self.group_alive():
            if time.monotonic() > deadline:
                return False
            self.popen.poll()  # reap the leader
            time.sleep(0.05)
        return True

    def kill(self) -> None:
        """SIGKILL the whole group and reap the leader (idempotent)."""
        self.signal_group(signal.SIGKILL)
        try:
            self.popen.wait(timeout=10)
        except subprocess.TimeoutExpired:  # pragma: no cover
            pass

    def launched_exits(self) -> dict[str, int]:
        """Exit status of each process ``ros2 launch`` reported (0 = finished cleanly)."""
        text = self.output()
        return {
            m['proc']: int(m['code']) if m['code'] is not None else 0
            for m in _LAUNCH_EXIT.finditer(text)
        }

    def launched_processes(self) -> list[str]:
        """Names of the processes ``ros2 launch`` started (``simulator``, ``recorder`` ...)."""
        return [m['proc'] for m in _LAUNCH_START.finditer(self.output())]


class Ros2:
    """Runs ``ros2`` (or a command of the install tree) in one test's environment.

    Parameters
    ----------
    cli : Ros2Cli
        The command line.
    env : dict
        The environment (with the test's domain).
    workdir : Path
        Working directory and place of the output logs.
    """

    def __init__(self, cli: Ros2Cli, env: dict[str, str], workdir: Path) -> None:
        self.cli = cli
        self.env = env
        self.workdir = workdir
        self.started: list[Ros2Process] = []
        self._count = itertools.count()

    def command(self, *args: str) -> list[str]:
        """``ros2 <args>`` as an argument list."""
        return [str(self.cli.executable), *map(str, args)]

    def run(self, *args: str, timeout: float = RUN_TIMEOUT) -> subprocess.CompletedProcess:
        """Run ``ros2 <args>`` to its end; stdout and stderr captured as text."""
        return self.run_command(self.command(*args), timeout=timeout)

    def run_command(
        self, argv: list[str], timeout: float = RUN_TIMEOUT
    ) -> subprocess.CompletedProcess:
        """Run any command in the environment (its own session; killed on timeout)."""
        proc = subprocess.Popen(
            argv, env=self.env, cwd=self.workdir, stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            start_new_session=True,
        )  # fmt: skip
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            pytest.fail(f'{argv} did not end within {timeout} s:\n{out[-4000:]}\n{err[-4000:]}')
        return subprocess.CompletedProcess(argv, proc.returncode, out, err)

    def start(self, *args: str) -> Ros2Process:
        """Start ``ros2 <args>`` in its own session (see :class:`Ros2Process`)."""
        return self.start_command(self.command(*args))

    def start_command(self, argv: list[str]) -> Ros2Process:
        """Start any command in the environment, in its own session."""
        log = self.workdir / f'process-{next(self._count)}.log'
        with open(log, 'wb') as sink:
            popen = subprocess.Popen(
                argv, env=self.env, cwd=self.workdir, stdin=subprocess.DEVNULL,
                stdout=sink, stderr=subprocess.STDOUT, start_new_session=True,
            )  # fmt: skip
        started = Ros2Process(list(argv), popen, log)
        self.started.append(started)
        return started

    def close(self) -> None:
        """Kill whatever this test started and left running."""
        for started in self.started:
            if started.popen.poll() is None or started.group_alive():
                started.kill()


@pytest.fixture
def ros2(ros2_env: Ros2Env, domain: int, tmp_path: Path):
    """A :class:`Ros2` runner for one test (its leftovers are killed at the end)."""
    env = _in_domain(ros2_env.env, domain) | {'ROS_LOG_DIR': str(tmp_path / 'ros_log')}
    runner = Ros2(ros2_env.cli, env, tmp_path)
    yield runner
    runner.close()
