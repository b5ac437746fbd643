"""The main job is deterministic: the same seed prints the same figures, run after run.

The first run after an install compiles the numba kernels, and later runs load
them from numba's cache. Both must give the very same numbers: a kernel whose
floating-point result depends on where LLVM inlined it (fast-math
reassociation) made the first run's settled RMS differ from every later one.
Each run here is a process of its own on a fresh, private kernel cache
(``NUMBA_CACHE_DIR``): the first compiles, the second loads.
"""

import os
import re
import subprocess
import sys

import pytest

RUN_TIMEOUT = 900  # s: the first run compiles every kernel of the lab (~1-2 min of CPU)


def _figures(printed: str, out: str) -> list[str]:
    """The printed lines without the run's wall-clock times and output paths."""
    lines = []
    for line in printed.splitlines():
        line = line.replace(out, '<out>')
        line = re.sub(r'simulated in [0-9.]+ s, [0-9.]+ x real time', 'simulated in <wall>', line)
        lines.append(line)
    return lines


@pytest.mark.timeout(2 * RUN_TIMEOUT)
def test_two_runs_of_the_main_job_print_the_same_figures_the_first_compiling(domain, tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / 'numba'))
    printed = []
    for run in ('first', 'second'):
        out = str(tmp_path / run)
        argv = ['--duration', '0.2', '--settle', '0.2', '--seed', '3', '--no-plots', '--quiet']
        done = subprocess.run(
            [sys.executable, '-m', 'maglev_ros.cli.lab', *argv, '--out', out],
            env=env,
            capture_output=True,
            text=True,
            timeout=RUN_TIMEOUT,
            check=False,
        )
        assert done.returncode in (0, 1), done.stdout + done.stderr
        printed.append(_figures(done.stdout, out))
    assert any('settled after' in line for line in printed[0]), printed[0]
    assert printed[0] == printed[1]
