"""Observers of the control loop: they see its samples and never hold it up.

An observer is any callable taking a :class:`~maglev_ros.loop.LoopSample`.
Called in the loop's thread it must be quick (an array log, a counter). A
slow one (a publisher, a recorder, an online identifier) goes behind an
:class:`ObserverThread`: the loop only appends to a bounded queue, a thread of
the observer's own drains it, and when the queue is full the sample is dropped
and counted, as ros2_control's ``RealtimePublisher::try_publish`` skips a
message rather than wait.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

__all__ = ['Observer', 'ObserverSet', 'ObserverThread']

Observer = Callable[[Any], None]


class ObserverSet:
    """The loop's observers, each called with every ``every``-th sample.

    Parameters
    ----------
    observers : iterable of Observer or (Observer, every)
        ``every`` >= 1 (default 1: every sample).
    """

    def __init__(self, observers: Iterable[Observer | tuple[Observer, int]] = ()) -> None:
        self._entries: list[list] = []
        for entry in observers:
            self.add(*entry) if isinstance(entry, tuple) else self.add(entry)

    def add(self, observer: Observer, every: int = 1) -> None:
        """Call ``observer`` with every ``every``-th sample from now on.

        Parameters
        ----------
        observer : Observer
        every : int
            Decimation, >= 1.
        """
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise ValueError(f'every must be an integer >= 1, got {every!r}')
        self._entries.append([observer, every, 0])

    def remove(self, observer: Observer) -> None:
        """Stop calling ``observer``."""
        self._entries = [e for e in self._entries if e[0] != observer]

    def __bool__(self) -> bool:
        return bool(self._entries)

    def __call__(self, sample) -> None:
        """Hand ``sample`` to the observers whose turn it is."""
        for entry in self._entries:
            if entry[1] == 1:
                entry[0](sample)
                continue
            entry[2] += 1
            if entry[2] >= entry[1]:
                entry[2] = 0
                entry[0](sample)


class ObserverThread:
    """Run a slow observer in a thread of its own, behind a bounded queue.

    Calling it appends the sample and returns at once; when ``depth`` samples
    are waiting, the new one is dropped and counted in :attr:`dropped`.

    Parameters
    ----------
    observer : Observer
        Called with each queued sample, in order, in this object's thread.
    depth : int
        Samples that may wait.
    name : str
        The thread's name.
    """

    def __init__(self, observer: Observer, depth: int = 10000, name: str = 'maglev-observer'):
        if isinstance(depth, bool) or not isinstance(depth, int) or depth < 1:
            raise ValueError(f'depth must be an integer >= 1, got {depth!r}')
        self.observer = observer
        self.depth = depth
        self.dropped = 0
        self.delivered = 0
        self.error: BaseException | None = None
        self._queue: deque = deque()
        self._wake = threading.Event()
        self._closing = False
        self._thread = threading.Thread(target=self._drain, name=name, daemon=True)
        self._thread.start()

    def __call__(self, sample) -> None:
        """Queue ``sample`` (dropped and counted when the queue is full)."""
        if len(self._queue) >= self.depth or self.error is not None:
            self.dropped += 1
            return
        self._queue.append(sample)
        self._wake.set()

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait until every queued sample was delivered; False on a timeout.

        Parameters
        ----------
        timeout : float
            s.
        """
        done = threading.Event()
        self._queue.append(done)
        self._wake.set()
        return done.wait(timeout)

    def close(self, timeout: float = 10.0) -> None:
        """Deliver what is queued, then stop the thread.

        Parameters
        ----------
        timeout : float
            s to wait for the thread.
        """
        self._closing = True
        self._wake.set()
        self._thread.join(timeout)

    def __enter__(self) -> ObserverThread:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _drain(self) -> None:
        queue = self._queue
        while True:
            self._wake.wait()
            self._wake.clear()
            while queue:
                item = queue.popleft()
                if isinstance(item, threading.Event):
                    item.set()
                    continue
                if self.error is not None:
                    continue
                try:
                    self.observer(item)
                    self.delivered += 1
                except BaseException as err:  # noqa: BLE001 - reported, the loop goes on
                    self.error = err
            if self._closing:
                return
