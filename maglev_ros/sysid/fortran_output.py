"""Keep text that LAPACK's Fortran runtime writes to file descriptor 1 off the terminal.

LAPACK reports an illegal argument (``** On entry to DLASCL parameter number 4
had an illegal value``) by writing to the process's standard output from
Fortran, below Python's ``sys.stdout``: redirecting ``sys.stdout`` does not
catch it, and it corrupts machine-readable output such as ``--json``. The
estimators guard the inputs that cause it (non-finite systems); this context
manager is the second line: it points fd 1 at a temporary file for the
duration of a numerical call and hands back what was written there.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field

__all__ = ['CapturedText', 'captured_fd_stdout']


@dataclass
class CapturedText:
    """What was written to fd 1 inside :func:`captured_fd_stdout` (filled on exit).

    Attributes
    ----------
    text : str
        The captured text, stripped; empty if nothing was written.
    """

    text: str = field(default='')


@contextlib.contextmanager
def captured_fd_stdout() -> Iterator[CapturedText]:
    """Redirect file descriptor 1 to a temporary file; yield what was written.

    Python's own ``sys.stdout`` is flushed before and after, so earlier
    ``print`` output of the caller is not captured.
    Not for code that runs other threads writing to stdout meanwhile.

    Yields
    ------
    CapturedText
        Holder whose ``text`` is set when the block ends.
    """
    holder = CapturedText()
    fd = 1  # Fortran unit 6 is fd 1, whatever sys.stdout is
    sys.stdout.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile(mode='w+b') as sink:
        os.dup2(sink.fileno(), fd)
        try:
            yield holder
        finally:
            sys.stdout.flush()
            os.dup2(saved, fd)
            os.close(saved)
            sink.seek(0)
            holder.text = sink.read().decode(errors='replace').strip()
