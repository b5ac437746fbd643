"""Nodes spun on threads for a test: the threads stop before their executors shut down.

An executor shut down while its thread is inside ``spin`` can fail that thread: a
callback's task triggers a guard condition the shutdown destroyed
(``InvalidHandle``), a warning of the test run. :class:`Spinning` spins with
``spin_once`` until told to stop, joins the threads, then shuts the executors down.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor


class Spinning:
    """Each node on its own executor and thread, until :meth:`close`.

    Parameters
    ----------
    context : rclpy.context.Context
        The test's context.
    nodes : iterable of rclpy.node.Node
        The nodes to spin.
    period : float
        s each ``spin_once`` waits at most (how soon :meth:`close` is noticed).
    """

    def __init__(self, context, nodes: Iterable, period: float = 0.05) -> None:
        self._stop = threading.Event()
        self._period = period
        self._executors = []
        self._threads = []
        for node in nodes:
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            thread = threading.Thread(target=self._spin, args=(executor,), daemon=True)
            thread.start()
            self._executors.append(executor)
            self._threads.append(thread)

    def _spin(self, executor) -> None:
        try:
            while not self._stop.is_set():
                executor.spin_once(timeout_sec=self._period)
        except ExternalShutdownException:  # the context went first
            pass

    def close(self, timeout: float = 2.0) -> None:
        """Stop the threads, then shut the executors down (each within ``timeout`` s)."""
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout)
        for executor in self._executors:
            executor.shutdown(timeout_sec=timeout)
