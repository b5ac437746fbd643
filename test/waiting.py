"""The one polling helper of the tests: wait until a condition holds, or fail."""

from __future__ import annotations

import time
from collections.abc import Callable

TIMEOUT = 30.0  # s, generous: the machine is shared


def wait_for(
    predicate: Callable[[], object],
    timeout: float = TIMEOUT,
    what: str = 'condition',
    period: float = 0.005,
) -> None:
    """Poll ``predicate`` every ``period`` s until true; fail naming ``what`` after ``timeout`` s.

    Parameters
    ----------
    predicate : callable
        Returns a truthy value once the condition holds.
    timeout : float
        s to wait at most.
    what : str
        What is waited for, for the failure message.
    period : float
        s between polls (longer for a predicate that runs a command).
    """
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(period)
