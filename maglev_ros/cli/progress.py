"""Progress bars for long work in the ``maglev-*`` tools (tqdm on stderr).

A bar is drawn only when stderr is a terminal and ``--quiet`` is not given;
otherwise every call is a no-op, so logs and pipes stay clean.
"""

from __future__ import annotations

import sys

from tqdm import tqdm

__all__ = ['progress_bar', 'stage']

_FORMAT = '{desc}: {percentage:3.0f}%|{bar}| {n:.3g}/{total:.3g} {unit} [{elapsed}<{remaining}]'
_PERCENT = '{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]'


def progress_bar(total: float | None, desc: str, unit: str, quiet: bool = False) -> tqdm:
    """Return a tqdm bar on stderr, disabled when quiet or stderr is not a terminal.

    Parameters
    ----------
    total : float or None
        Amount of work in ``unit`` (None: unknown, a counter).
    desc : str
        Short description shown before the bar.
    unit : str
        Unit of ``total`` (``'s'`` of simulated time, ``'it'``, ...).
    quiet : bool
        ``--quiet``: no bar whatever the terminal.

    Returns
    -------
    tqdm
        Use as a context manager; ``update(n)`` advances, ``set_postfix_str``
        adds a status.
    """
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=True if quiet else None,  # None: off when stderr is not a TTY
        leave=False,
        dynamic_ncols=True,
        bar_format=(_PERCENT if unit == '%' else _FORMAT) if total else None,
    )


def stage(text: str, quiet: bool = False) -> tqdm:
    """Return a one-line status (``text...``) on stderr for a step of unknown length.

    Shown, like :func:`progress_bar`, only on a terminal and without ``--quiet``;
    cleared when the context ends.

    Parameters
    ----------
    text : str
        What is being done, e.g. ``'finding the equilibrium'``.
    quiet : bool
        ``--quiet``: nothing.

    Returns
    -------
    tqdm
        Use as a context manager.
    """
    return tqdm(
        total=None,
        desc=text,
        file=sys.stderr,
        disable=True if quiet else None,
        leave=False,
        bar_format='{desc}...',
    )
