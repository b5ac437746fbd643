"""Stop on SIGINT, SIGTERM or SIGHUP without being killed in the clean-up.

A terminal's Ctrl-C reaches a whole ``ros2 launch`` process group, and launch
then sends its own SIGINT: a node gets two signals, the second one while it
finalises its bag or zeroes the coils. Python's default SIGINT handler (and
rclpy's, which chains to it) raises ``KeyboardInterrupt`` wherever the main
thread happens to be, also inside that clean-up; SIGHUP (a closed terminal or
SSH session) and, outside rclpy, SIGTERM kill the process outright.

:class:`StopSignals` turns each of these signals into a request to stop: the
first one sets :attr:`StopSignals.event` (the caller's loop ends and its
clean-up runs); later ones are counted and otherwise ignored, so the clean-up
always runs to its end. Pure Python; no ROS.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterable
from types import FrameType, TracebackType

__all__ = ['STOP_SIGNALS', 'StopSignals']

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopSignals:
    """Handle stop signals as a request to stop (a context manager).

    Handlers are installed on ``__enter__``. ``__exit__`` restores the previous
    ones if no signal came; after a signal it ignores these signals from then
    on (``SIG_IGN``, which Python keeps through its own finalisation), since the
    process is on its way out and launch's SIGINT may come after the clean-up.
    Outside the main thread (where Python cannot install signal
    handlers) nothing is installed and :attr:`event` is only set by
    :meth:`request`.

    Parameters
    ----------
    signals : iterable of signal.Signals, optional
        The signals to handle (default SIGINT, SIGTERM and SIGHUP).

    Attributes
    ----------
    event : threading.Event
        Set by the first signal.
    signum : int or None
        The first signal received.
    received : int
        Signals received in all.
    """

    def __init__(self, signals: Iterable[signal.Signals] = STOP_SIGNALS) -> None:
        self.signals = tuple(signals)
        self.event = threading.Event()
        self.signum: int | None = None
        self.received = 0
        self._previous: dict[int, object] = {}

    @property
    def requested(self) -> bool:
        """True once a stop signal arrived (or :meth:`request` was called)."""
        return self.event.is_set()

    @property
    def exit_status(self) -> int:
        """The shell's status for the first signal, ``128 + signum`` (0 before any)."""
        return 128 + self.signum if self.signum is not None else 0

    def request(self) -> None:
        """Ask to stop, as a signal would (from any thread)."""
        self.event.set()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        # Re-entrant: a signal may interrupt this very handler (a flood of them,
        # or launch's SIGINT right after the terminal's). Only the first one
        # touches the Event, whose lock a nested handler must not wait for.
        self.received += 1
        if self.signum is None:
            self.signum = signum
            self.event.set()

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for signum in self.signals:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, signal.SIG_IGN if self.requested else previous)
        self._previous.clear()
