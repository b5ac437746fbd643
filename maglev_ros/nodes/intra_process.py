"""Samples, estimates and commands handed over inside one process.

rclpy has no intra-process communication: two composed nodes exchange
messages through the middleware, serialised, as if they ran in two
processes. At 5 kHz that is most of the cost of a composed closed loop (the
field of each sensor and the currents, 20 000 messages a second), and the
hops between the simulator's stepping thread and the executor's thread wait
for the GIL: a command then reaches the simulator milliseconds late, and the
loop, whose x and y modes grow e-fold in 20-35 ms, is lost. rclcpp's answer
is intra-process communication (``use_intra_process_comms``): a publisher
hands its message to the subscriptions of its own process directly. This
module does the same for the closed loop's three streams:

- the **simulator** (or the board **driver**, ``intra_process: true``)
  registers a :class:`Channel` of its published sample batches under the
  resolved name of its ``maglev/currents`` topic, and a :class:`CommandSink`
  under ``maglev/currents/command``;
- the **estimator** (``intra_process: true``, created after the simulator)
  connects to the samples and registers a channel of its estimates under
  ``maglev/state/estimate``;
- the **controller** (``intra_process: true``, ``trigger: estimate``, created
  after both) connects to the estimates and attaches to the sink: its
  commands go to the simulator directly, and the simulator stops taking
  commands from the middleware (one command source, no command twice).

Then one burst is stepped, estimated and answered in the simulator's thread,
and the command drives the next burst: the loop's latency is one burst
whatever the CPU load (a busy machine slows the simulation, not the loop).
Every topic is still published for the other subscribers (plots, the ROS
tools). A node that finds nothing to connect to uses the middleware as usual.

The **recorder** and the **identifier** (``intra_process: true``) take any
topic's messages as the publishing node serialised them: a
:class:`MessageTap` per topic (:func:`tap`) that the simulator (its samples,
``/clock``) and the controller (commands, excitation) feed with each burst's
bytes when someone listens. A tap with a publisher in the process replaces the
subscription (messages from other processes on that topic are then not taken).

A :class:`TapDispatcher` (:func:`dispatch_taps`) moves the taps' listeners
behind the loop's answer: every tap of the context then queues what it is
given, and the loop's thread hands it on (:func:`pump_taps`) once its command
is sent, in the order it was given (a command still follows the samples it
answers). A board's command leaves before any recording or identifying is
done (``maglev-lab --board``: a board waits for nobody). A thread of their
own would not do: with the interpreter's lock, the loop's thread would wait
for it at every call that releases the lock.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = [
    'Channel',
    'CommandSink',
    'MessageTap',
    'SampleBlock',
    'TapDispatcher',
    'dispatch_taps',
    'find',
    'pump_taps',
    'register',
    'tap',
    'unregister',
]

_lock = threading.Lock()
_registry: dict[tuple[int, str], object] = {}
_taps: dict[tuple[int, str], MessageTap] = {}
_dispatchers: dict[int, TapDispatcher] = {}  # per context (id)


@dataclass(frozen=True)
class SampleBlock:
    """Samples a sample :class:`Channel` delivers (what the simulator's batches also carry).

    Attributes
    ----------
    stamps_ns : ndarray of int64, shape (n,)
        Sample stamps, ns (ROS time).
    readings : ndarray, shape (n, 3 K)
        The fields of the channel's K sensors, T.
    currents : ndarray, shape (n, 4)
        Coil currents, A (x+ x- y+ y-).
    """

    stamps_ns: np.ndarray
    readings: np.ndarray
    currents: np.ndarray

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])


class Channel:
    """What one node publishes on a topic, for listeners in its process.

    Parameters
    ----------
    sensors : tuple of int, optional
        A sample channel: the sensors whose fields the simulator publishes.
    """

    def __init__(self, sensors: tuple[int, ...] = ()) -> None:
        self.sensors = tuple(sensors)
        self._listeners: tuple[tuple[str, Callable], ...] = ()
        self.on_error: Callable[[str, Exception], None] | None = None

    @property
    def listeners(self) -> int:
        """Listeners connected."""
        return len(self._listeners)

    def connect(self, listener: Callable, name: str) -> None:
        """Add ``listener``, called with what is delivered, in the publisher's thread.

        Parameters
        ----------
        listener : callable
            Takes the delivered arguments.
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

    def deliver(self, *args) -> None:
        """Call every listener; one that raises is reported, the rest still run.

        Parameters
        ----------
        *args
            What the listeners take (a sample batch; a stamp and an estimate).
        """
        for name, listener in self._listeners:
            try:
                listener(*args)
            except Exception as err:  # noqa: BLE001 - the publisher goes on
                if self.on_error is not None:
                    self.on_error(name, err)


class MessageTap(Channel):
    """The serialised messages of one topic inside a process (see the module docstring).

    Publishers call :meth:`add_publisher` (with their message class) when created and
    :meth:`remove_publisher` when destroyed, and :meth:`deliver` a list of
    CDR messages (``bytes``, in publishing order) when :attr:`listeners` is
    not zero; a listener takes that list, in the publisher's thread (or when
    the context's :class:`TapDispatcher` is pumped).

    Parameters
    ----------
    context_key : int, optional
        ``id`` of the context whose dispatcher, if any, hands the messages on.
    """

    def __init__(self, context_key: int = 0) -> None:
        super().__init__()
        self.publishers = 0
        self.msgtype = ''
        self._context_key = context_key

    def deliver(self, messages: list) -> None:
        """Hand ``messages`` to the listeners, or to the context's dispatcher's queue.

        Parameters
        ----------
        messages : list of bytes
            CDR messages, in publishing order.
        """
        dispatcher = _dispatchers.get(self._context_key)
        if dispatcher is not None and not dispatcher.pumping:
            dispatcher.put(self, messages)
        else:
            super().deliver(messages)

    def add_publisher(self, msg_class: type) -> None:
        """Count a publisher of this process.

        Parameters
        ----------
        msg_class : type
            Its message class (e.g. ``sensor_msgs.msg.MagneticField``): the
            tap's :attr:`msgtype` becomes ``sensor_msgs/msg/MagneticField``.
        """
        with _lock:
            self.publishers += 1
            self.msgtype = f'{msg_class.__module__.split(".")[0]}/msg/{msg_class.__name__}'

    def remove_publisher(self) -> None:
        """Uncount a publisher (destroyed)."""
        with _lock:
            self.publishers = max(self.publishers - 1, 0)


class TapDispatcher:
    """Defers the taps' deliveries of a context until its loop has answered (module docstring).

    Every tap of the context queues what it is given; the loop's thread
    calls :meth:`pump` once its command is sent, and the listeners get the
    queued messages then, in the order given (a command still follows the
    samples it answers). One thread does all the work, so no thread waits
    for another's share of the interpreter.
    """

    def __init__(self) -> None:
        self._queue: deque = deque()
        self._pumping = False

    @property
    def pumping(self) -> bool:
        """Whether :meth:`pump` is handing messages on (listeners' own deliveries go direct)."""
        return self._pumping

    def put(self, tap: MessageTap, messages: list) -> None:
        """Queue ``messages`` for ``tap``'s listeners (any thread).

        Parameters
        ----------
        tap : MessageTap
        messages : list of bytes
        """
        self._queue.append((tap, messages))

    @property
    def backlog(self) -> int:
        """Deliveries queued and not yet handed on."""
        return len(self._queue)

    def pump(self) -> None:
        """Hand on everything queued, in order (the loop's thread, after its command)."""
        self._pumping = True
        try:
            while self._queue:
                tap, messages = self._queue.popleft()
                Channel.deliver(tap, messages)
        finally:
            self._pumping = False

    close = pump


class CommandSink:
    """The simulator's command input, for one controller of its process.

    Parameters
    ----------
    take : callable
        Applies one command (a sequence of currents, A).
    on_attach : callable
        Called once a controller attaches (the simulator then drops its
        middleware subscription).
    lock : threading.RLock, optional
        The lock ``take`` acquires (the simulator's). A controller that
        attaches guards its own state with it too: one lock, one order, for
        its commands from the simulator's thread and from its executor's.
    """

    def __init__(self, take: Callable, on_attach: Callable[[str], None], lock=None) -> None:
        self.take = take
        self._on_attach = on_attach
        self.lock = lock
        self.attached: str | None = None

    def attach(self, name: str) -> Callable | None:
        """Become the simulator's command source; return the command input (None: taken).

        Parameters
        ----------
        name : str
            The controller's node name.
        """
        with _lock:
            if self.attached is not None:
                return None
            self.attached = name
        self._on_attach(name)
        return self.take


def _key(context, topic: str) -> tuple[int, str]:
    return id(context), topic


def register(context, topic: str, obj) -> None:
    """Register ``obj`` (a Channel or CommandSink) for ``topic`` (resolved name) in ``context``.

    Parameters
    ----------
    context : rclpy.context.Context
        The nodes' context.
    topic : str
        Fully qualified topic name.
    obj : Channel or CommandSink
        What a node of this process may connect to.
    """
    with _lock:
        _registry[_key(context, topic)] = obj


def unregister(context, topic: str, obj) -> None:
    """Remove ``obj`` (a later registration for the topic is left alone).

    Parameters
    ----------
    context : rclpy.context.Context
    topic : str
    obj : Channel or CommandSink
    """
    with _lock:
        if _registry.get(_key(context, topic)) is obj:
            del _registry[_key(context, topic)]


def find(context, topic: str):
    """Return what is registered for ``topic`` in ``context``, or None.

    Parameters
    ----------
    context : rclpy.context.Context
    topic : str
        Fully qualified topic name.
    """
    with _lock:
        return _registry.get(_key(context, topic))


def tap(context, topic: str) -> MessageTap:
    """Return the :class:`MessageTap` of ``topic`` in ``context`` (created at first use).

    Parameters
    ----------
    context : rclpy.context.Context
        The nodes' context.
    topic : str
        Fully qualified topic name.
    """
    key = _key(context, topic)
    with _lock:
        found = _taps.get(key)
        if found is None:
            found = _taps[key] = MessageTap(id(context))
        return found


def pump_taps(context) -> None:
    """Hand on what the taps of ``context`` queued, if it has a dispatcher (the loop's thread).

    Parameters
    ----------
    context : rclpy.context.Context
        The nodes' context.
    """
    dispatcher = _dispatchers.get(id(context))
    if dispatcher is not None:
        dispatcher.pump()


def dispatch_taps(context, dispatcher: TapDispatcher | None) -> None:
    """Let ``dispatcher`` defer every tap's messages in ``context`` (None: back to direct).

    Parameters
    ----------
    context : rclpy.context.Context
        The nodes' context.
    dispatcher : TapDispatcher or None
        The queue the loop pumps; None: each publisher delivers at once again
        (close the dispatcher afterwards: what it has queued is still handed on).
    """
    with _lock:
        if dispatcher is None:
            _dispatchers.pop(id(context), None)
        else:
            _dispatchers[id(context)] = dispatcher
