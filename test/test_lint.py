"""Linters run as tests: the tree is ruff-clean (pycodestyle, pyflakes, numpy docstrings)."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _ruff() -> str | None:
    beside = Path(sys.executable).parent / 'ruff'
    return str(beside) if beside.exists() else shutil.which('ruff')


def test_ruff_clean():
    ruff = _ruff()
    if ruff is None:
        pytest.skip('ruff is not installed (pip install ".[test]")')
    result = subprocess.run(
        [ruff, 'check', '--no-cache', 'maglev_ros', 'test', 'benchmarks'],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_ruff_format_clean():
    ruff = _ruff()
    if ruff is None:
        pytest.skip('ruff is not installed (pip install ".[test]")')
    result = subprocess.run(
        [ruff, 'format', '--check', '--no-cache', 'maglev_ros', 'test', 'benchmarks'],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, 'run `ruff format`:\n' + result.stdout + result.stderr
