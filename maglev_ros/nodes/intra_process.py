"""Samples handed from the simulator to the estimator inside one process.

rclpy has no intra-process communication: two composed nodes exchange
messages through the middleware, serialised, as if they ran in two
processes. At 5 kHz that is most of the cost of a composed closed loop (the
field of each sensor and the currents, 20 000 messages a second, each
serialised, sent, taken and decoded), and with it a composed simulator,
estimator and controller do not keep up with real time in Python. rclcpp's
answer is intra-process communication (``use_intra_process_comms``):
a publisher hands its message to the subscriptions of its own process
directly. This module does the same for the one stream that needs it:

- the simulator node registers a :class:`SampleSource` under its context and
  the resolved name of its ``maglev/currents`` topic;
- a node created after it in the same context (the estimator with
  ``intra_process: true``) finds it with :func:`find_source` and connects a
  listener, which then receives each published batch of samples (the very
  arrays the messages are serialised from, so the same numbers) in the
  simulator's publishing thread, after the batch's messages went out;
- the topics are still published for every other subscriber (recorder,
  plots, the ROS tools), and the node that connected does not subscribe
  to them.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ['SampleSource', 'find_source', 'register_source', 'unregister_source']

_lock = threading.Lock()
_sources: dict[tuple[int, str], SampleSource] = {}


class SampleSource:
    """The samples one simulator node publishes, for listeners in its process.

    Parameters
    ----------
    sensors : tuple of int
        The sensors whose fields the simulator publishes.
    """

    def __init__(self, sensors: tuple[int, ...]) -> None:
        self.sensors = tuple(sensors)
        self._listeners: tuple[Callable, ...] = ()
        self.on_error: Callable[[str, Exception], None] | None = None

    @property
    def connected(self) -> bool:
        """Whether a listener is connected."""
        return bool(self._listeners)

    @property
    def listeners(self) -> int:
        """Listeners connected."""
        return len(self._listeners)

    def connect(self, listener: Callable, name: str) -> None:
        """Add ``listener``: called with each published batch (a ``SampleBatch``).

        Parameters
        ----------
        listener : callable
            Takes the batch; runs in the simulator's publishing thread.
        name : str
            Who listens (for error messages).
        """
        with _lock:
            self._listeners = (*self._listeners, (name, listener))

    def disconnect(self, listener: Callable) -> None:
        """Remove ``listener`` (no error if it is not connected).

        Parameters
        ----------
        listener : callable
            As given to :meth:`connect`.
        """
        with _lock:
            self._listeners = tuple(item for item in self._listeners if item[1] != listener)

    def deliver(self, batch) -> None:
        """Hand ``batch`` to every listener; one that raises is reported, the rest still run.

        Parameters
        ----------
        batch : maglev_ros.physics.session.SampleBatch
            The samples just published.
        """
        for name, listener in self._listeners:
            try:
                listener(batch)
            except Exception as err:  # noqa: BLE001 - the simulator goes on
                if self.on_error is not None:
                    self.on_error(name, err)


def _key(context, topic: str) -> tuple[int, str]:
    return id(context), topic


def register_source(context, topic: str, source: SampleSource) -> None:
    """Make ``source`` the samples of ``topic`` (resolved name) in ``context``.

    Parameters
    ----------
    context : rclpy.context.Context
        The nodes' context.
    topic : str
        Fully qualified name of the simulator's currents topic.
    source : SampleSource
        The simulator's source.
    """
    with _lock:
        _sources[_key(context, topic)] = source


def unregister_source(context, topic: str, source: SampleSource) -> None:
    """Remove ``source`` (a later simulator's registration is left alone).

    Parameters
    ----------
    context : rclpy.context.Context
    topic : str
    source : SampleSource
    """
    with _lock:
        if _sources.get(_key(context, topic)) is source:
            del _sources[_key(context, topic)]


def find_source(context, topic: str) -> SampleSource | None:
    """Return the source of ``topic`` in ``context``, or None (no simulator in this process).

    Parameters
    ----------
    context : rclpy.context.Context
    topic : str
        Fully qualified name of the currents topic.
    """
    with _lock:
        return _sources.get(_key(context, topic))
