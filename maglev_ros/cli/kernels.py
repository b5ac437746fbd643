"""Fill an installed package's numba kernel cache: what ``colcon build`` runs last.

``python -m maglev_ros.cli.kernels [--seed-from SRC]`` copies the kernels a
source checkout has compiled (:func:`maglev_ros.kernel_cache.seed`), compiles
the rest with a short lab session (:func:`maglev_ros.kernel_cache.compile_kernels`)
and, where ROS 2 is installed, runs the loop node's message encoders on a few
loop samples, so that a node started right after the build loads every kernel
from the cache. ``setup.py``'s install step calls it; run it by hand after a
``colcon build --symlink-install`` (its modules live in the source tree).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import maglev_ros
from maglev_ros.kernel_cache import compile_kernels, seed

__all__ = ['compile_encoders', 'main']


def compile_encoders(samples: int = 20) -> bool:
    """Encode ``samples`` loop samples as the loop node publishes them; False without ROS.

    Parameters
    ----------
    samples : int
        Loop samples to run and encode.
    """
    try:
        from maglev_ros.nodes.broadcast import LoopEncoder
    except ImportError:  # no ROS 2 here: the nodes are not used either
        return False
    from maglev_ros.loop.simulated_setup import SimulatedLoopSettings, build_loop

    loop, plant = build_loop(SimulatedLoopSettings(), None)
    encode = LoopEncoder(plant.simulator.model.n_outputs // 3, true_state=True)

    def observe(s) -> None:
        encode.sample(s)
        encode.clock(s)
        if s.estimate is not None:
            encode.estimate(s)
        if s.command is not None:
            encode.command(s)

    loop.observers.add(observe)
    loop.run(samples)
    return True


def main(argv: list[str] | None = None) -> int:
    """Seed and fill the package's kernel cache (see the module docstring).

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.
    """
    p = argparse.ArgumentParser(
        prog='python -m maglev_ros.cli.kernels', description=__doc__.splitlines()[0]
    )
    p.add_argument('--seed-from', type=Path, help='package directory of a source checkout')
    args = p.parse_args(argv)
    installed = Path(maglev_ros.__file__).resolve().parent
    copied = seed(args.seed_from.resolve(), installed) if args.seed_from else 0
    print(
        f'maglev_ros: compiling the numba kernels into {installed} ({copied} cache files '
        'copied from the source; up to ~60 s, once per build; MAGLEV_BUILD_COMPILE=0 skips)',
        flush=True,
    )
    took = compile_kernels()
    encoders = 'and the message encoders ' if compile_encoders() else ''
    print(f'maglev_ros: kernels {encoders}ready ({took:.0f} s)', flush=True)
    return 0


if __name__ == '__main__':  # pragma: no cover
    sys.exit(main())
