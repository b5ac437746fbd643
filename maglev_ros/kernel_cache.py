"""The numba kernel cache of an install: seeded and filled when the package is built.

numba compiles a kernel on its first call and keeps the machine code in its
on-disk cache (``cache=True``: an ``*.nbi`` index and ``*.nbc`` data files in
``__pycache__`` beside each module), keyed by the module's *content* (a hash
of its source, numba >= 0.59), not by its path. ``colcon build`` installs the
modules into a fresh ``install/`` tree, where nothing is cached yet, so without
this module the first node started by ``ros2 launch`` after a build would
compile for 20 to 50 s before it publishes.

``setup.py``'s install step (what ``colcon build`` runs) therefore calls
``python -m maglev_ros.cli.kernels --seed-from SRC`` on the installed package:

1. :func:`seed` copies the entries the source checkout has compiled already
   (a checkout where the main job or the tests ran): valid by content, so a
   stale one is simply ignored by numba;
2. :func:`compile_kernels` runs a short lab session (the closed loop with the
   default estimator, controller, bag recorder and online identifier), which
   compiles whatever is still missing into the install tree;
3. with ROS 2 present, the loop node's message encoders run on a few loop
   samples (``maglev_ros.cli.kernels``).

After it, the nodes started with their default parameters load their kernels
from the cache. ``MAGLEV_BUILD_COMPILE=0`` skips the step (the first start
then compiles). Pure Python, no ROS.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

__all__ = ['compile_kernels', 'seed']

_ENTRIES = '__pycache__/*.nb[ic]'


def seed(source: Path, installed: Path) -> int:
    """Copy the kernels compiled in a source tree into an installed copy of the package.

    Parameters
    ----------
    source : Path
        The package directory of the source tree (``.../maglev_ros``).
    installed : Path
        The same package where it is installed.

    Returns
    -------
    int
        The number of cache files copied (0 when the source has none).
    """
    copied = 0
    for cached in sorted(source.rglob(_ENTRIES)):
        target = installed / cached.relative_to(source)
        if not target.parent.parent.is_dir():  # a module the install does not have
            continue
        target.parent.mkdir(exist_ok=True)
        shutil.copy2(cached, target)
        copied += 1
    return copied


def compile_kernels() -> float:
    """Compile (or load) the kernels a default lab session and the nodes use; return s.

    Runs ``maglev-lab`` for 0.2 s of simulated levitation without plots in a
    temporary directory: the simulator, the KF, the LQR, the bag recorder and
    the online identifier, with the parameters the nodes start with.

    Returns
    -------
    float
        Wall time taken, s.
    """
    from maglev_ros.cli import lab

    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix='maglev-kernels-') as tmp:
        args = ['--out', str(Path(tmp) / 'lab'), '--duration', '0.2', '--settle', '0.2']
        status = lab.main([*args, '--no-plots', '--quiet'])
    if status:
        raise RuntimeError(f'the short lab session ended with status {status}')
    return time.monotonic() - start
