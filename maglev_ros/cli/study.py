r"""``maglev-study``: Monte Carlo and region-of-attraction studies of the closed loop.

Runs every run of a study file (YAML: what is fixed, on a grid, drawn at
random; see ``docs/studies.md``) through the package's ROS-free closed loop,
locally on every core (an embedded Dask cluster: nothing to start) or on a
running Dask cluster::

    maglev-study roa.yaml                          # local, every core
    maglev-study roa.yaml --workers 1              # local, one worker process
    maglev-study roa.yaml --scheduler tcp://10.0.0.5:8786
    maglev-study roa.yaml --resume                 # continue an interrupted study
    maglev-study --list                            # the parameters a study may set

Results go to ``--out`` (default: ``<study>_results/`` next to the file): the
table (``results.parquet`` with pyarrow, ``results.csv`` without), figures,
``summary.txt``. Ctrl-C keeps the finished runs; ``--resume`` does the rest.
Exit status: 0 done, 2 bad input (one line on stderr), 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from .usage import Parser, UsageError, limit_blas_threads, run_command

__all__ = ['build_parser', 'main']

PROG = 'maglev-study'


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-study``."""
    parser = Parser(
        prog=PROG,
        description='Monte Carlo and region-of-attraction studies of the closed loop.',
        epilog='Study files: docs/studies.md. Exit status 2 on bad input, 130 on Ctrl-C.',
    )
    parser.add_argument('study', nargs='?', help='study file (YAML)')
    parser.add_argument('--out', type=Path, help='results directory (default: <study>_results)')
    where = parser.add_mutually_exclusive_group()
    where.add_argument('--scheduler', metavar='tcp://HOST:PORT', help='run on this Dask cluster')
    where.add_argument(
        '--serial', action='store_true', help='run in this process (no Dask; for debugging)'
    )
    parser.add_argument('--workers', type=int, help='local worker processes (default: every core)')
    parser.add_argument('--resume', action='store_true', help='continue the study in --out')
    parser.add_argument('--no-plots', action='store_true', help='table and summary only')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.add_argument('--list', action='store_true', help='list the study parameters and exit')
    return parser


def _list() -> int:
    from maglev_ros.study.parameters import PARAMETERS

    width = max(len(k) for k in PARAMETERS)
    for key, p in PARAMETERS.items():
        unit = f' [{p.unit}]' if p.unit and p.unit != 'SI' else ''
        print(f'{key:<{width}}  {p.kind:<7}  default {p.default!r}{unit}: {p.description}')
    return 0


def _run(args: argparse.Namespace) -> int:
    if args.list:
        return _list()
    if not args.study:
        raise UsageError('give a study file (maglev-study --list shows the parameters)')
    if args.workers is not None and args.workers < 1:
        raise UsageError(f'--workers must be at least 1, got {args.workers}')
    if args.workers is not None and (args.scheduler or args.serial):
        raise UsageError('--workers is for the local cluster, not with --scheduler or --serial')
    from tqdm import tqdm

    from maglev_ros.study import (
        DaskBackend,
        SerialBackend,
        StudyInterrupted,
        load_study,
        plan_runs,
        plot_study,
        run_study,
        summary,
    )

    limit_blas_threads(1)
    spec = load_study(args.study)
    plan_runs(spec)  # every value checked before a worker starts
    out = args.out or Path(args.study).with_name(f'{Path(args.study).stem}_results')
    started = time.perf_counter()
    bar = None

    def on_start(done: int, total: int) -> None:
        nonlocal bar
        bar = tqdm(
            total=total,
            initial=done,
            desc=spec.name,
            unit='run',
            file=sys.stderr,
            disable=True if args.quiet else None,
            dynamic_ncols=True,
        )

    def on_row(row: dict) -> None:
        bar.update(1)

    backend = SerialBackend() if args.serial else DaskBackend(args.scheduler, args.workers)
    print(f'{PROG}: {spec.n_runs} runs of {spec.duration:g} s on {backend.where}', file=sys.stderr)
    try:
        with backend:
            result = run_study(spec, out, backend, args.resume, on_row=on_row, on_start=on_start)
    except StudyInterrupted as stop:
        if bar is not None:
            bar.close()
        part = stop.partial
        print(
            f'{PROG}: interrupted after {len(part.rows)} of {part.total} runs; they are kept in '
            f'{part.table}; continue with: maglev-study {args.study} --out {out} --resume',
            file=sys.stderr,
        )
        return 130
    finally:
        if bar is not None:
            bar.close()
    varied = [k for k in spec.grid if len(spec.grid[k]) > 1]
    text = summary(result.rows, varied, result.total)
    (out / 'summary.txt').write_text(text + '\n', encoding='utf-8')
    figures = [] if args.no_plots else plot_study(spec, result.rows, out)
    print(text)
    elapsed = time.perf_counter() - started
    print(f'table: {result.table} ({elapsed:.0f} s)')
    for path in figures:
        print(f'figure: {path}')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``maglev-study``; return the exit status (2 on bad input, 130 when interrupted).

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments (default: the command line).
    """
    return run_command(PROG, build_parser(), _run, argv)


if __name__ == '__main__':
    sys.exit(main())
