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
import sys
from collections.abc import Callable, Sequence

__all__ = [
    'UsageError',
    'Parser',
    'limit_blas_threads',
    'run_command',
    'positive_float',
    'non_negative_float',
]


class UsageError(ValueError):
    """Invalid command-line input (exit status 2)."""


class Parser(argparse.ArgumentParser):
    """An ArgumentParser that raises :class:`UsageError` instead of printing usage."""

    def error(self, message: str) -> None:  # noqa: D102 - one-line usage errors
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
    """Argparse type: a finite number > 0."""
    value = _finite_number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f'must be positive, got {text!r}')
    return value


def non_negative_float(text: str) -> float:
    """Argparse type: a finite number >= 0."""
    value = _finite_number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be >= 0, got {text!r}')
    return value


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
    try:
        args = parser.parse_args(None if argv is None else list(argv))
        return run(args)
    except SystemExit as exc:  # --help / --version
        return int(exc.code or 0)
    except (ValueError, OSError) as exc:
        text = str(exc).strip().splitlines()
        message = text[0] if text else type(exc).__name__
        print(f'{prog}: error: {message}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'{prog}: interrupted', file=sys.stderr)
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
