"""Per-sample streams taken in a thread of their own, a burst at a time.

At 5 kHz a node that estimates every sample receives 20 000 messages a second
(the field of each of three sensors and the currents). Through an executor
each message is a dispatch of its own: rclpy's EventsExecutor, called a
``spin_once`` at a time (its ``spin()`` holds the GIL while it waits, so no
other thread of the process runs), and an estimator process at 5 kHz fell
behind the samples at a whole core. :class:`SampleStreams` takes those
subscriptions out of the executor: a thread waits on one wait set for all of
them and, when it wakes, takes every message already there (raw CDR, ~5 us
each) and hands them to the node at once (``burst``) or to the streams'
callbacks a message per topic per round, in the order the topics were given
(:func:`dispatch_round_robin`: a sample's messages are handled together),
then waits again. The simulator
and the driver publish a millisecond's samples at once, so one wake-up
serves a burst. The node's other entities (timers, services, low-rate
topics) stay on its executor.

The subscriptions are rcl subscriptions of the node (``ros2 node info``
lists them, QoS as given) that the node's executor does not see. They use
rclpy's wait-set and subscription handles, as ``rclpy.wait_for_message``
does; where those are missing (another rclpy), :func:`open_streams` falls
back to ordinary executor subscriptions with the same callbacks.

Callbacks run in the streams' thread: state they share with the node's
executor callbacks (e.g. counters read by a diagnostics timer) is read
under the GIL, one Python operation at a time.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

__all__ = ['SampleStreams', 'Stream', 'dispatch_round_robin', 'open_streams']

_WAIT_NS = 100_000_000  # a wake-up at least every 0.1 s: close() is seen


@dataclass(frozen=True)
class Stream:
    """One subscribed topic: its message type, name and raw-bytes callback."""

    msg_type: type
    topic: str
    callback: Callable[[bytes], None]


class SampleStreams:
    """Subscribe to ``streams`` and take their messages in a thread of its own.

    Parameters
    ----------
    node : rclpy.node.Node
        The node the subscriptions belong to.
    streams : sequence of Stream
        The topics, taken in this order at each wake-up (put the message that
        completes a sample last, e.g. the currents after the fields).
    qos : rclpy.qos.QoSProfile
        QoS of every subscription.
    on_error : callable, optional
        Called with an exception a callback raised (the thread keeps running);
        default: the node's logger, throttled.
    burst : callable, optional
        Called once per wake-up with every message taken, a list of raw
        messages per stream (in the order of ``streams``, each in arrival
        order), instead of the streams' own callbacks: the node handles a
        burst at once.

    Raises
    ------
    AttributeError, TypeError
        If this rclpy lacks the wait-set or subscription handles used.
    """

    def __init__(
        self,
        node,
        streams: Sequence[Stream],
        qos,
        on_error: Callable[[Exception], None] | None = None,
        burst: Callable[[list[list[bytes]]], None] | None = None,
    ) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
        from rclpy.type_support import check_is_valid_msg_type

        self._node = node
        self._context = node.context
        self._streams = list(streams)
        self._on_error = on_error or self._log_error
        self._burst = burst
        self._callbacks = [stream.callback for stream in self._streams]
        self._handles = []
        c_qos = qos.get_c_qos_profile()
        for stream in self._streams:
            check_is_valid_msg_type(stream.msg_type)  # loads the type support
            with node.handle:
                self._handles.append(
                    _rclpy.Subscription(node.handle, stream.msg_type, stream.topic, c_qos)
                )
        self._guard = _rclpy.GuardCondition(self._context.handle)
        self._wait_set = _rclpy.WaitSet(len(self._handles), 1, 0, 0, 0, 0, self._context.handle)
        self._stop = threading.Event()
        self._closed = False
        self.taken = 0  # messages taken
        self.wake_ups = 0
        self._thread = threading.Thread(
            target=self._run, name=f'{node.get_name()}-streams', daemon=True
        )
        self._thread.start()
        self._context.on_shutdown(self._wake_to_stop)  # the thread ends with the context

    def _wake_to_stop(self) -> None:
        self._stop.set()
        try:
            self._guard.trigger_guard_condition()
        except Exception:  # noqa: BLE001 - already destroyed: the wait ends by timeout
            pass

    def _log_error(self, err: Exception) -> None:
        self._node.get_logger().error(
            f'sample stream callback failed: {err}', throttle_duration_sec=1.0
        )

    def _run(self) -> None:
        ws, handles, guard = self._wait_set, self._handles, self._guard
        pairs = [(h, s.msg_type, s.callback) for h, s in zip(handles, self._streams, strict=True)]
        while not self._stop.is_set():
            try:
                ws.clear_entities()
                for handle in handles:
                    ws.add_subscription(handle)
                ws.add_guard_condition(guard)
                ws.wait(_WAIT_NS)
            except Exception:  # noqa: BLE001 - the context was shut down under us
                if self._stop.is_set() or not self._context.ok():
                    return
                raise
            if self._stop.is_set():
                return
            self.wake_ups += 1
            if not self._take_burst(pairs):
                return

    def _take_burst(self, pairs) -> bool:
        """Take every waiting message of each stream, hand them over at once; False: stop."""
        lists: list[list[bytes]] = []
        for handle, msg_type, _ in pairs:
            here: list[bytes] = []
            while True:
                try:
                    taken = handle.take_message(msg_type, True)
                except Exception:  # noqa: BLE001 - the subscription is being destroyed
                    return False
                if taken is None:
                    break
                here.append(taken[0])
            lists.append(here)
            self.taken += len(here)
        if not any(lists):  # woken by the timeout or the stop guard
            return True
        if self._burst is None:  # the streams' own callbacks, each message on its own
            dispatch_round_robin(lists, self._callbacks, self._on_error)
            return True
        try:
            self._burst(lists)
        except Exception as err:  # noqa: BLE001 - a node never dies on a message
            self._on_error(err)
        return True

    def publisher_count(self, index: int) -> int:
        """Return how many publishers are matched to a stream's subscription.

        Parameters
        ----------
        index : int
            The stream's position in the ``streams`` given.
        """
        return self._handles[index].get_publisher_count()

    def close(self) -> None:
        """Stop the thread and destroy the subscriptions (before the node)."""
        if self._closed:
            return
        self._closed = True
        self._wake_to_stop()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)
        for handle in self._handles:
            handle.destroy_when_not_in_use()
        self._guard.destroy_when_not_in_use()
        self._wait_set.destroy_when_not_in_use()


def dispatch_round_robin(lists, callbacks, on_error=None) -> None:
    """Call each stream's callback on its messages, a message per stream per round.

    The messages of one sample (one per stream, in stream order) are handled
    together, as an executor taking them as they arrive would.

    Parameters
    ----------
    lists : sequence of list of bytes
        The raw messages of each stream, in arrival order.
    callbacks : sequence of callable
        The callback of each stream.
    on_error : callable, optional
        Called with an exception a callback raised, then the next message is
        handled (default: the exception propagates).
    """
    for i in range(max((len(raws) for raws in lists), default=0)):
        for raws, callback in zip(lists, callbacks, strict=True):
            if i < len(raws):
                if on_error is None:
                    callback(raws[i])
                    continue
                try:
                    callback(raws[i])
                except Exception as err:  # noqa: BLE001 - a node never dies on a message
                    on_error(err)


def open_streams(node, streams: Sequence[Stream], qos, own_thread: bool = True, burst=None):
    """Subscribe to ``streams``: in a :class:`SampleStreams` thread, else on the executor.

    Parameters
    ----------
    node : rclpy.node.Node
        The node.
    streams : sequence of Stream
        Topics and their raw-bytes callbacks.
    qos : rclpy.qos.QoSProfile
        QoS of every subscription.
    own_thread : bool
        False: ordinary subscriptions on the node's executor.
    burst : callable, optional
        The burst callback of :class:`SampleStreams` (the executor's
        subscriptions call the streams' own callbacks).

    Returns
    -------
    SampleStreams or None
        The streams' thread (close it before destroying the node), or None
        when the subscriptions are the executor's.
    """
    if own_thread:
        try:
            return SampleStreams(node, streams, qos, burst=burst)
        except (AttributeError, TypeError, ImportError) as err:
            node.get_logger().warning(
                f'sample streams on the executor (this rclpy has no wait-set handles: {err})'
            )
    for stream in streams:
        node.create_subscription(stream.msg_type, stream.topic, stream.callback, qos, raw=True)
    return None
