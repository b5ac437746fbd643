"""Fixtures of the tests through the real ROS 2 command line (``ros2 run/param``).

The package is built with colcon into a temporary workspace once per session;
``ros2`` is the Jazzy command line that ``../shared/ros2-cli/install.sh``
installs next to the test's Python. Where either is missing, the tests skip
with the reason. Every process gets its own ROS domain (the ids of
``test/nodes/conftest.py``) and localhost discovery; processes run in their
own session, so a test can send SIGINT to the whole group as a terminal does.
"""

from __future__ import annotations

import itertools
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest

PACKAGE = 'maglev_ros'
PKG_DIR = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
ROS2 = BIN / 'ros2'
COLCON = BIN / 'colcon'
BUILD_TIMEOUT = 300  # s
SAFE_DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
_DOMAINS = itertools.count((os.getpid() * 7) % len(SAFE_DOMAIN_IDS))
_IGNORED = {'__pycache__', '.pytest_cache', '.ruff_cache', '.git', '.venv', 'build', 'install'}


def _ignore(directory: str, names: list[str]) -> set[str]:
    ignored = {n for n in names if n in _IGNORED or n.endswith('.egg-info')}
    if Path(directory).resolve() != PKG_DIR:
        ignored -= {'build', 'install'}  # only the top-level colcon trees
    return ignored


@dataclass(frozen=True)
class Ros2Env:
    """A colcon install of the package and the environment to run ``ros2`` in it.

    Attributes
    ----------
    prefix : Path
        The package's install prefix.
    env : dict
        Environment as ``source install/setup.bash`` would leave it (domain
        id and discovery range set per call by :meth:`run`/:meth:`start`).
    """

    prefix: Path
    env: dict

    def _env(self, domain: int) -> dict:
        return self.env | {
            'ROS_DOMAIN_ID': str(domain),
            'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        }

    def run(
        self, args: Sequence[str], domain: int, timeout: float = 60.0
    ) -> subprocess.CompletedProcess:
        """Run ``ros2 args...`` to completion (stdout and stderr captured as text)."""
        return subprocess.run(
            [str(ROS2), *args],
            env=self._env(domain),
            capture_output=True,
            text=True,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
        )

    def start(self, args: Sequence[str], domain: int) -> subprocess.Popen:
        """Start ``ros2 args...`` in its own session (output merged into stdout)."""
        return subprocess.Popen(
            [str(ROS2), *args],
            env=self._env(domain),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        )


def interrupt(proc: subprocess.Popen, timeout: float = 30.0) -> tuple[int, str]:
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


def wait_until(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll ``predicate`` every 0.5 s until true; fail naming ``what`` after ``timeout`` s."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            pytest.fail(f'timed out after {timeout} s waiting for {what}')
        time.sleep(0.5)


@pytest.fixture(scope='session')
def ros2_env(tmp_path_factory: pytest.TempPathFactory) -> Ros2Env:
    """Build the package with colcon once; skip where ``ros2`` or colcon is missing."""
    if not ROS2.is_file():
        pytest.skip(
            f'no ros2 command next to {sys.executable} (bash ../shared/ros2-cli/install.sh)'
        )
    if not COLCON.is_file():
        pytest.skip(f'colcon is not installed next to {sys.executable}')
    workspace = tmp_path_factory.mktemp('ros2cli') / 'ws'
    shutil.copytree(PKG_DIR, workspace / 'src' / PACKAGE, ignore=_ignore)
    env = os.environ.copy()
    env['COLCON_HOME'] = str(workspace.parent / 'colcon_home')
    env.pop('COLCON_DEFAULTS_FILE', None)
    env['PATH'] = os.pathsep.join(filter(None, [str(BIN), env.get('PATH')]))
    proc = subprocess.run(
        [str(COLCON), 'build', '--base-paths', 'src', '--packages-select', PACKAGE],
        cwd=workspace,
        env=env,
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
        stdin=subprocess.DEVNULL,
    )
    if proc.returncode != 0:
        pytest.fail(f'colcon build failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}')
    prefix = workspace / 'install' / PACKAGE
    (site,) = prefix.glob('lib/python3*/site-packages')
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(site), env.get('PYTHONPATH')]))
    env['AMENT_PREFIX_PATH'] = os.pathsep.join([str(prefix), str(BIN.parent)])
    env['PYTHONNOUSERSITE'] = '1'
    env['PYTHONUNBUFFERED'] = '1'
    return Ros2Env(prefix, env)


@pytest.fixture
def domain() -> int:
    """A ROS domain id of its own for one test."""
    return SAFE_DOMAIN_IDS[next(_DOMAINS) % len(SAFE_DOMAIN_IDS)]
