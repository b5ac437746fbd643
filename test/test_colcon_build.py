"""Build the package with colcon and check what lands in the install tree.

The build is the session fixture ``colcon_build`` of ``test/conftest.py`` (the
package source copied into a temporary workspace, ``colcon build
--packages-select maglev_ros`` once per session, a plain copy install, which is
what ``ros2 run`` users get by default). This module checks the
console scripts, the ament index marker, ``package.xml``, the config and launch
files, that an installed console script runs, and that the build compiled the
loop node's kernels.
"""

from __future__ import annotations

import ast
import filecmp
import importlib.metadata
import os
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from conftest import ColconBuild

PACKAGE = 'maglev_ros'
PKG_DIR = Path(__file__).resolve().parents[1]
RUN_TIMEOUT = 120


def _tail(text: str, limit: int = 12000) -> str:
    return text if len(text) <= limit else '[...]\n' + text[-limit:]


def _setup_py_names() -> set[str]:
    """Keys of the ``CLI_TOOLS`` and ``NODES`` dict literals in ``setup.py``."""
    tree = ast.parse((PKG_DIR / 'setup.py').read_text(), filename='setup.py')
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        else:
            continue
        if any(isinstance(t, ast.Name) and t.id in ('CLI_TOOLS', 'NODES') for t in targets):
            names.update(ast.literal_eval(value))
    return names


def _installed_console_scripts(build: ColconBuild) -> set[str]:
    """Console script names from the metadata of the distribution colcon installed."""
    dists = [
        d
        for d in importlib.metadata.distributions(path=[str(build.site_packages())])
        if (d.metadata['Name'] or '').replace('-', '_').lower() == PACKAGE
    ]
    assert len(dists) == 1, f'expected one {PACKAGE} distribution in {build.site_packages()}'
    return {ep.name for ep in dists[0].entry_points if ep.group == 'console_scripts'}


def test_colcon_build_succeeds(colcon_build: ColconBuild) -> None:
    assert colcon_build.returncode == 0, colcon_build.report()
    assert colcon_build.prefix.is_dir(), colcon_build.report()


def test_console_scripts_installed(colcon_build: ColconBuild) -> None:
    colcon_build.require()
    declared = _installed_console_scripts(colcon_build)
    assert declared, 'the built distribution declares no console_scripts'
    # The metadata must cover every tool and node named in setup.py.
    missing_decl = _setup_py_names() - declared
    assert not missing_decl, f'setup.py names not in console_scripts: {sorted(missing_decl)}'

    lib_dir = colcon_build.lib_dir
    present = sorted(p.name for p in lib_dir.iterdir()) if lib_dir.is_dir() else []
    for name in sorted(declared):
        script = lib_dir / name
        assert script.is_file(), f'{name} not installed in {lib_dir} (found: {present})'
        assert not script.is_symlink(), f'{script} is a symlink in a copy install'
        assert os.access(script, os.X_OK), f'{script} is not executable'
        first_line = script.read_text().splitlines()[0]
        assert first_line.startswith('#!'), f'{script} has no shebang: {first_line!r}'
        interpreter = Path(first_line[2:].strip().split()[0])
        assert os.access(interpreter, os.X_OK), f'{script}: interpreter {interpreter} missing'


def test_ament_index_marker(colcon_build: ColconBuild) -> None:
    colcon_build.require()
    marker = colcon_build.prefix / 'share/ament_index/resource_index/packages' / PACKAGE
    assert marker.is_file(), f'ament index marker missing: {marker}'


def test_package_xml_installed(colcon_build: ColconBuild) -> None:
    colcon_build.require()
    installed = colcon_build.share_dir / 'package.xml'
    assert installed.is_file(), f'{installed} missing'
    assert filecmp.cmp(installed, PKG_DIR / 'package.xml', shallow=False)


def test_config_files_installed(colcon_build: ColconBuild) -> None:
    colcon_build.require()
    sources = sorted((PKG_DIR / 'config').glob('*.yaml'))
    assert sources, f'no config/*.yaml in {PKG_DIR}'
    dest = colcon_build.share_dir / 'config'
    for src in sources:
        installed = dest / src.name
        assert installed.is_file(), f'config/{src.name} not installed in {dest}'
        assert filecmp.cmp(installed, src, shallow=False), f'{installed} differs from {src}'


def test_launch_files_installed(colcon_build: ColconBuild) -> None:
    colcon_build.require()
    launch = PKG_DIR / 'launch'
    sources = sorted(
        p
        for p in (launch.rglob('*') if launch.is_dir() else [])
        if p.is_file() and '__pycache__' not in p.parts
    )
    dest = colcon_build.share_dir / 'launch'
    for src in sources:
        installed = dest / src.relative_to(launch)
        assert installed.is_file(), f'launch/{src.relative_to(launch)} not installed in {dest}'
        assert filecmp.cmp(installed, src, shallow=False), f'{installed} differs from {src}'


def test_installed_package_is_imported(colcon_build: ColconBuild) -> None:
    """The run environment picks the installed copy, not the editable source."""
    colcon_build.require()
    code = (
        'import importlib.metadata as m, maglev_ros; '
        "print(maglev_ros.__file__); print(m.distribution('maglev_ros').locate_file(''))"
    )
    proc = subprocess.run(
        [sys.executable, '-c', code], env=colcon_build.run_env(), capture_output=True,
        text=True, timeout=RUN_TIMEOUT, stdin=subprocess.DEVNULL,
        cwd=colcon_build.workspace.parent,  # not the source tree: '' leads sys.path
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    site = colcon_build.site_packages().resolve()
    for line in proc.stdout.splitlines():
        assert Path(line).resolve().is_relative_to(site), f'{line} is not under {site}'


@pytest.mark.parametrize('verb', ['model', 'sysid', 'calibrate'])
def test_installed_cli_runs(colcon_build: ColconBuild, verb: str) -> None:
    colcon_build.require()
    if not (PKG_DIR / PACKAGE / 'cli' / f'{verb}.py').is_file():
        pytest.skip(f'{PACKAGE}/cli/{verb}.py does not exist yet: nothing to run')
    script = colcon_build.lib_dir / verb
    assert script.is_file(), f'{script} not installed'
    proc = subprocess.run(
        [str(script), '--help'], env=colcon_build.run_env(), capture_output=True,
        text=True, timeout=RUN_TIMEOUT, stdin=subprocess.DEVNULL,
        cwd=colcon_build.workspace.parent,
    )  # fmt: skip
    assert proc.returncode == 0, (
        f'{script} --help exited with {proc.returncode}\n'
        f'--- stdout ---\n{_tail(proc.stdout)}\n--- stderr ---\n{_tail(proc.stderr)}'
    )
    assert 'usage' in proc.stdout.lower(), proc.stdout


_COUNT_COMPILES = """
from numba.core import event
compiles = []
class Count(event.Listener):
    def on_start(self, ev):
        compiles.append(getattr(ev.data.get('dispatcher'), '__qualname__', '?'))
    def on_end(self, ev):
        pass
event.register('numba:compile', Count())
from maglev_ros.cli.kernels import compile_encoders
assert compile_encoders()
print('compiled:', sorted(set(compiles)))
"""


def test_the_build_leaves_the_loop_nodes_kernels_compiled(colcon_build: ColconBuild) -> None:
    """Right after ``colcon build`` the loop node's kernels load from the install's cache.

    The build's last step (``maglev_ros.cli.kernels``) fills the cache, so the
    loop (simulator, KF, LQR) and its message encoders compile nothing when a
    node first runs them.
    """
    colcon_build.require()
    site = colcon_build.site_packages() / PACKAGE
    indexed = {p.name.split('-')[0] for p in site.rglob('__pycache__/*.nbi')}
    for kernel in ('kernels.sample_step', 'linear_kernels.kf_packed_step', 'kernels.lqr_law'):
        assert kernel in indexed, f'{kernel} not compiled by the build: {sorted(indexed)}'
    env = colcon_build.run_env()
    env.pop('NUMBA_CACHE_DIR', None)
    proc = subprocess.run(
        [sys.executable, '-c', _COUNT_COMPILES], env=env, capture_output=True, text=True,
        timeout=RUN_TIMEOUT, stdin=subprocess.DEVNULL, cwd=colcon_build.workspace.parent,
    )  # fmt: skip
    assert proc.returncode == 0, _tail(proc.stderr)
    assert 'compiled: []' in proc.stdout, proc.stdout + _tail(proc.stderr)
