"""Fixtures shared by every test directory: ROS domains and contexts, one colcon build.

``domain`` and ``ctx`` give each test its own ROS domain and rclpy Context
(tests that start nodes in this process: test/nodes, test/cli). Domain ids
come from the ranges whose DDS ports stay out of Linux's ephemeral port range
(32768-60999), 1-101 and 215-232, so a test's discovery ports never collide
with a random socket; every test of a session gets its own id.

``colcon_build`` copies the package source into a temporary workspace and runs
``colcon build --packages-select maglev_ros`` once per session (a plain copy
install, which is what ``ros2 run`` users get by default). The install-tree
checks (``test_colcon_build.py``) and the real command-line tests
(``test/ros2cli``) use the same build. The copy keeps the numba cache files the
source tree has compiled so far (``__pycache__/*.nbi``, ``*.nbc``), as a
user's checkout does: the build's last step (``maglev_ros.cli.kernels``)
copies them into the install tree and compiles the rest.

Tests send SIGINT to the commands they start, as a terminal's Ctrl-C does. A
test run started as a background job of a non-interactive shell (``.ci/run &``)
inherits SIGINT ignored, and so would every command it starts (an ignored
signal stays ignored across ``exec``): the session restores Python's handler
first, so its commands get the default disposition.
"""

from __future__ import annotations

import itertools
import os
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

PACKAGE = 'maglev_ros'
PKG_DIR = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).parent / 'colcon'

BUILD_TIMEOUT = 600  # s; the build compiles the kernels the checkout has not (~45 s of CPU)


def pytest_configure(config):
    """Take SIGINT back from an ignoring parent (see the module docstring)."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


SAFE_DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
_NEXT = itertools.count(os.getpid() % len(SAFE_DOMAIN_IDS))


def next_domain_id() -> int:
    """A domain id not used yet in this session (wraps after 119 tests)."""
    return SAFE_DOMAIN_IDS[next(_NEXT) % len(SAFE_DOMAIN_IDS)]


@pytest.fixture
def domain(monkeypatch):
    """A ROS domain of its own for one test (``ROS_DOMAIN_ID``, localhost discovery)."""
    domain_id = next_domain_id()
    monkeypatch.setenv('ROS_DOMAIN_ID', str(domain_id))
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return domain_id


@pytest.fixture
def ctx(domain):
    """An initialised rclpy Context on the test's domain, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    yield context
    rclpy.try_shutdown(context=context)


# Excluded wherever they occur in the source tree (``__pycache__``: all but numba's cache).
_IGNORED_ANYWHERE = {'.pytest_cache', '.ruff_cache', '.mypy_cache'}
_NUMBA_CACHE = ('.nbi', '.nbc')
# Excluded only at the top of the package (a subpackage may well be called ``build``).
_IGNORED_AT_TOP = {'.git', '.venv', 'venv', 'build', 'install', 'log'}


def _ignore(directory: str, names: list[str]) -> set[str]:
    if Path(directory).name == '__pycache__':
        return {n for n in names if not n.endswith(_NUMBA_CACHE)}
    ignored = {n for n in names if n in _IGNORED_ANYWHERE or n.endswith('.egg-info')}
    if Path(directory).resolve() == PKG_DIR:
        ignored |= _IGNORED_AT_TOP.intersection(names)
    return ignored


def tail(text: str, limit: int = 12000) -> str:
    """The last ``limit`` characters of ``text`` (marked when cut)."""
    return text if len(text) <= limit else '[...]\n' + text[-limit:]


@dataclass
class ColconBuild:
    """Result of one ``colcon build`` in a temporary workspace."""

    workspace: Path
    returncode: int | None
    stdout: str
    stderr: str

    @property
    def prefix(self) -> Path:
        return self.workspace / 'install' / PACKAGE

    @property
    def lib_dir(self) -> Path:
        return self.prefix / 'lib' / PACKAGE

    @property
    def share_dir(self) -> Path:
        return self.prefix / 'share' / PACKAGE

    def report(self) -> str:
        log = self.workspace / 'log' / 'latest_build' / PACKAGE / 'stdout_stderr.log'
        log_text = log.read_text(errors='replace') if log.is_file() else f'({log} missing)'
        return (
            f'colcon build in {self.workspace} exited with {self.returncode}\n'
            f'--- colcon stdout ---\n{tail(self.stdout)}\n'
            f'--- colcon stderr ---\n{tail(self.stderr)}\n'
            f'--- {log.relative_to(self.workspace)} ---\n{tail(log_text)}'
        )

    def require(self) -> None:
        if self.returncode != 0:
            pytest.fail('colcon build failed (details in test_colcon_build_succeeds)')

    def site_packages(self) -> Path:
        found = sorted(self.prefix.glob('lib/python3*/site-packages'))
        assert len(found) == 1, f'expected one site-packages dir under {self.prefix}: {found}'
        return found[0]

    def run_env(self) -> dict[str, str]:
        """Environment roughly as ``source install/setup.bash`` would leave it."""
        env = os.environ.copy()
        site = str(self.site_packages())
        env['PYTHONPATH'] = os.pathsep.join(filter(None, [site, env.get('PYTHONPATH')]))
        env['AMENT_PREFIX_PATH'] = os.pathsep.join(
            filter(None, [str(self.prefix), env.get('AMENT_PREFIX_PATH')])
        )
        env['PYTHONNOUSERSITE'] = '1'
        return env


@pytest.fixture(scope='session')
def colcon_build(tmp_path_factory: pytest.TempPathFactory) -> ColconBuild:
    """The package built once per session with colcon (skips without colcon)."""
    if not COLCON.is_file():
        pytest.skip(
            f'colcon is not installed next to {sys.executable} '
            "(pip install 'colcon-common-extensions')"
        )
    workspace = tmp_path_factory.mktemp('colcon') / 'ws'
    shutil.copytree(PKG_DIR, workspace / 'src' / PACKAGE, ignore=_ignore)

    env = os.environ.copy()
    # Keep the user's colcon defaults and mixins out of the build.
    env['COLCON_HOME'] = str(workspace.parent / 'colcon_home')
    env.pop('COLCON_DEFAULTS_FILE', None)
    env['PATH'] = os.pathsep.join(filter(None, [str(COLCON.parent), env.get('PATH')]))
    cmd = [
        str(COLCON), 'build',
        '--base-paths', 'src',
        '--packages-select', PACKAGE,
        '--event-handlers', 'console_direct-',
    ]  # fmt: skip
    try:
        proc = subprocess.run(
            cmd, cwd=workspace, env=env, capture_output=True, text=True,
            timeout=BUILD_TIMEOUT, stdin=subprocess.DEVNULL,
        )  # fmt: skip
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode(errors='replace') if isinstance(exc.stdout, bytes) else ''
        err = exc.stderr.decode(errors='replace') if isinstance(exc.stderr, bytes) else ''
        return ColconBuild(workspace, None, out, err + f'\n(timed out after {BUILD_TIMEOUT} s)')
    return ColconBuild(workspace, proc.returncode, proc.stdout, proc.stderr)


@pytest.fixture(scope='session')
def main_job(tmp_path_factory: pytest.TempPathFactory):
    """README command 1 (the main job), run once per session for the README and the pages.

    Returns a ``doc_blocks.MainJob``: the directory it ran in (``lab/`` inside) and
    what it printed.
    """
    from doc_blocks import run_main_job

    return run_main_job(tmp_path_factory.mktemp('main_job'), next_domain_id())


@pytest.fixture(scope='session')
def v2():
    """The maggy_v2 model, built once per session."""
    from maglev_ros.physics import make_model

    return make_model('maggy_v2')


@pytest.fixture(scope='session')
def v2_linear(v2):
    """Its linearisation at the hover equilibrium."""
    from maglev_ros.physics import linearize

    return linearize(v2)


@pytest.fixture(scope='session')
def v4():
    """The maggy_v4 model, built once per session."""
    from maglev_ros.physics import make_model

    return make_model('maggy_v4')


@pytest.fixture(scope='session')
def v4_linear(v4):
    """Its linearisation at the hover equilibrium."""
    from maglev_ros.physics import linearize

    return linearize(v4)
