"""Bringing up nodes composed in one process: a context, one spinning executor, a clean close."""

from __future__ import annotations

import time

import rclpy
from rclpy.context import Context
from rclpy.signals import SignalHandlerOptions

from maglev_ros.nodes.runtime import Spinner

__all__ = ['WAIT_S', 'Bringup']

WAIT_S = 60.0  # s, default longest wait of Bringup.wait_until (discovery, draining)


def _stop_requested(stop) -> bool:
    """Whether ``stop`` (a StopSignals, a threading.Event or None) asks to stop."""
    if stop is None:
        return False
    requested = getattr(stop, 'requested', None)
    return bool(requested) if requested is not None else stop.is_set()


class Bringup:
    """Nodes composed in this process, spun on one executor in a background thread.

    Add the nodes (each built with ``context=bringup.context``), :meth:`start`
    spinning, :meth:`wait_until` the graph is ready (discovery), run, then
    :meth:`close` (or use it as a context manager): the spinner stops, the
    nodes are destroyed in the reverse order of :attr:`nodes` and the context
    shuts down.

    Parameters
    ----------
    context : rclpy.context.Context, optional
        An initialised context, shut down by :meth:`close`. Default: a new
        one, initialised without command-line arguments and without rclpy's
        signal handlers (the caller handles signals, e.g. with
        :class:`maglev_ros.stop_signals.StopSignals`).

    Attributes
    ----------
    context : rclpy.context.Context
        The nodes' context.
    nodes : list of rclpy.node.Node
        The nodes added, in the order they are destroyed last to first.
    """

    def __init__(self, context: Context | None = None) -> None:
        if context is None:
            context = Context()
            rclpy.init(context=context, args=[], signal_handler_options=SignalHandlerOptions.NO)
        self.context = context
        self.nodes: list = []
        self._spinner: Spinner | None = None
        self._closed = False

    def add(self, node, *, destroy_last: bool = False):
        """Add a node (to the executor too once spinning) and return it.

        Parameters
        ----------
        node : rclpy.node.Node
            The node, built on :attr:`context`.
        destroy_last : bool
            Destroy it after every node added so far (e.g. a recorder: the bag
            is finalised once the nodes writing to it are gone).

        Returns
        -------
        rclpy.node.Node
            ``node``.
        """
        if destroy_last:
            self.nodes.insert(0, node)
        else:
            self.nodes.append(node)
        if self._spinner is not None:
            self._spinner.add_node(node)
        return node

    def start(self) -> None:
        """Start spinning the nodes added so far in a background thread (once)."""
        if self._spinner is None:
            self._spinner = Spinner(self.context, self.nodes)

    def wait_until(self, predicate, what: str, timeout: float = WAIT_S, stop=None) -> None:
        """Wait (polling every 10 ms) until ``predicate()`` is true.

        Parameters
        ----------
        predicate : callable
            Called without arguments from this thread; true ends the wait.
        what : str
            What is waited for, named in the timeout's message (e.g. ``'the
            node graph'``).
        timeout : float
            Longest wait, s.
        stop : StopSignals or threading.Event, optional
            Ends the wait with KeyboardInterrupt once it is requested (set).

        Raises
        ------
        RuntimeError
            After ``timeout`` seconds: ``timed out after <timeout> s waiting for <what>``.
        KeyboardInterrupt
            If ``stop`` is requested or the context shuts down.
        """
        deadline = time.monotonic() + timeout
        while not predicate():
            if not self.context.ok() or _stop_requested(stop):
                raise KeyboardInterrupt
            if time.monotonic() > deadline:
                raise RuntimeError(f'timed out after {timeout:g} s waiting for {what}')
            time.sleep(0.01)

    def close(self) -> None:
        """Stop spinning, destroy the nodes (last added first), shut the context down.

        Idempotent.
        """
        if self._closed:
            return
        self._closed = True
        try:
            if self._spinner is not None:
                self._spinner.close()
            for node in reversed(self.nodes):
                node.destroy_node()
        finally:
            rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> Bringup:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
