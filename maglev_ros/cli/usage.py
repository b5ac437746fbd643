"""Command-line conventions shared by every ``maglev-*`` tool.

Bad input (arguments, files, values: a ``ValueError`` or ``OSError``) ends the
tool with exit status 2 and one line on stderr, ``<prog>: error: <what is
wrong>``, never a traceback. A programming error (``TypeError``,
``KeyError``, ...) is not bad input: it raises, with its traceback. Nothing
here changes the environment at import.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

__all__ = [
    'UsageError',
    'Parser',
    'check_output_dir',
    'check_output_file',
    'limit_blas_threads',
    'run_command',
    'positive_float',
    'non_negative_float',
]


class UsageError(ValueError):
    """Invalid command-line input (exit status 2)."""


class Parser(argparse.ArgumentParser):
    """An ArgumentParser that raises :class:`UsageError` instead of printing usage.

    Negative numbers in exponent notation (``--ts -2e-4``) are values, not
    options: argparse's own pattern knows only ``-2`` and ``-0.5``.

    Parameters
    ----------
    *args, **kwargs
        Passed to :class:`argparse.ArgumentParser`.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r'^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$')

    def error(self, message: str) -> None:
        """Raise :class:`UsageError` with argparse's message (no usage text, no exit).

        Parameters
        ----------
        message : str
            argparse's message.
        """
        raise UsageError(message)


def _finite_number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if value != value or value in (float('inf'), float('-inf')):
        raise argparse.ArgumentTypeError(f'must be finite, got {text!r}')
    return value


def positive_float(text: str) -> float:
    """Argparse type: a finite number > 0.

    Parameters
    ----------
    text : str
        The command-line text.
    """
    value = _finite_number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f'must be positive, got {text!r}')
    return value


def non_negative_float(text: str) -> float:
    """Argparse type: a finite number >= 0.

    Parameters
    ----------
    text : str
        The command-line text.
    """
    value = _finite_number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be >= 0, got {text!r}')
    return value


def _check_writable_place(option: str, path: Path, parent: Path, create_parents: bool) -> None:
    """Refuse ``path`` unless its directory ``parent`` exists (or can be made) and is writable."""
    shown = f'{option} {path}'
    place = parent
    while not place.exists() and place != place.parent:
        place = place.parent
    if not place.is_dir():
        raise UsageError(
            f'{shown}: {str(place)!r} is a file, not a directory: choose another path'
        )
    if not create_parents and not parent.is_dir():
        raise UsageError(f'{shown}: directory {str(parent)!r} does not exist: create it first')
    if not os.access(place, os.W_OK | os.X_OK):
        raise UsageError(f'{shown}: directory {str(place)!r} is not writable: choose another path')


def check_output_file(option: str, path: str | os.PathLike, create_parents: bool = True) -> None:
    """Check before any work that an output file can be written (:class:`UsageError` if not).

    Parameters
    ----------
    option : str
        The option that names the file (``'--out'``), for the message.
    path : str or path-like
        The file to be written.
    create_parents : bool
        The writer makes missing directories (else the file's directory must exist).

    Raises
    ------
    UsageError
        The path is a directory, a directory on the way is a file, or the
        directory that would hold it is not writable.
    """
    path = Path(path)
    if path.is_dir():
        raise UsageError(f'{option} {path}: is a directory: name a file')
    if path.exists() and not os.access(path, os.W_OK):
        raise UsageError(f'{option} {path}: the file is not writable: choose another path')
    _check_writable_place(option, path, path.parent, create_parents)


def check_output_dir(option: str, path: str | os.PathLike) -> None:
    """Check before any work that an output directory can be made and written.

    Parameters
    ----------
    option : str
        The option that names the directory (``'--plot'``), for the message.
    path : str or path-like
        The directory (made with its parents if missing).

    Raises
    ------
    UsageError
        The path or a directory on the way is a file, or it is not writable.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UsageError(f'{option} {path}: is a file, not a directory: choose another path')
    _check_writable_place(option, path, path, True)


def run_command(
    prog: str,
    parser: argparse.ArgumentParser,
    run: Callable[[argparse.Namespace], int],
    argv: Sequence[str] | None = None,
) -> int:
    """Parse ``argv`` and call ``run``; map bad input to one line and status 2.

    Parameters
    ----------
    prog : str
        Program name for the error line.
    parser : argparse.ArgumentParser
        The tool's parser (a :class:`Parser`).
    run : callable
        Takes the parsed arguments, returns the exit status.
    argv : sequence of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status: ``run``'s, 0 for ``--help``, 2 for bad input, 130 when
        interrupted.

    Raises
    ------
    Exception
        Anything but ``ValueError`` and ``OSError`` (a programming error),
        with its traceback.
    """
    from maglev_ros.compile_watch import CompileWatch, compile_estimate

    watch = CompileWatch(prog, compile_estimate(prog))
    try:
        args = parser.parse_args(None if argv is None else list(argv))
        with watch:
            status = run(args)
        watch.end_if_interrupted(status)  # stopped during a first run's compile: no teardown
        return status
    except SystemExit as exc:  # --help / --version
        return int(exc.code or 0)
    except (ValueError, OSError) as exc:
        text = str(exc).strip().splitlines()
        message = text[0] if text else type(exc).__name__
        print(f'{prog}: error: {message}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'{prog}: interrupted', file=sys.stderr)
        watch.end_if_interrupted(130)  # stopped during a first run's compile: no teardown
        return 130


_OPENBLAS_SETTERS = (
    'openblas_set_num_threads',
    'openblas_set_num_threads64_',
    'scipy_openblas_set_num_threads64_',
    'scipy_openblas_set_num_threads',
)


def limit_blas_threads(n_threads: int = 1) -> int:
    """Limit every OpenBLAS loaded in this process to ``n_threads`` threads.

    Small least-squares problems gain nothing from threaded BLAS, and on a
    shared machine its spinning threads can make a 2 ms solve take 400 ms.
    Called by a tool's run function, not at import (``OPENBLAS_NUM_THREADS``
    only acts before numpy loads); a library other than OpenBLAS, or a system
    without ``/proc``, is left alone.

    Parameters
    ----------
    n_threads : int
        Threads per library (>= 1).

    Returns
    -------
    int
        How many libraries were limited.
    """
    try:
        with open('/proc/self/maps') as maps:
            paths = {line.split()[-1] for line in maps if 'openblas' in line.lower()}
    except OSError:
        return 0
    limited = 0
    for path in sorted(paths):
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _OPENBLAS_SETTERS:
            setter = getattr(library, name, None)
            if setter is not None:
                setter(int(n_threads))
                limited += 1
                break
    return limited
