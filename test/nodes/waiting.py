"""The one polling helper of the node tests: wait until a condition holds, or fail."""

from __future__ import annotations

import time
from collections.abc import Callable

TIMEOUT = 30.0  # s, generous: the machine is shared


def wait_for(
    predicate: Callable[[], object], timeout: float = TIMEOUT, what: str = 'condition'
) -> None:
    """Poll ``predicate`` every 5 ms until it is true; fail naming ``what`` after ``timeout`` s.

    Parameters
    ----------
    predicate : callable
        Returns a truthy value once the condition holds.
    timeout : float
        s to wait at most.
    what : str
        What is waited for, for the failure message.
    """
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.005)
