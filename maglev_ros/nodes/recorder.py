"""Recorder node: ``ros2 run maglev_ros recorder``.

Writes chosen topics to a rosbag2 directory (MCAP by default, sqlite3 on
request) with rosbags (:class:`maglev_ros.bags.BagWriter`), so a pip-only
machine can record. Messages are stored as received (``raw=True``
subscriptions: the CDR bytes, no conversion). A topic is subscribed as soon as
its type appears in the graph; the subscription is RELIABLE if every
publisher offers reliable delivery, else BEST_EFFORT, with depth ``depth``.

Log times: ``log_clock = ros`` uses the node's clock (wall time, or ``/clock``
with ``use_sim_time``); ``topic`` uses the newest ``/clock`` message the
recorder received itself (``/clock`` must be among ``topics``): every message
of a lockstep run is then logged at the simulated time of its sample, which is
what the bag converter needs for header-less commands. ``stamp`` logs each
message with a header (and ``/clock``) at its own stamp and a header-less one
(commands) at the newest stamp recorded before it: with the simulator in real
time, where ``/clock`` goes once per burst, a command that answers a burst is
logged at the burst's last sample, which it follows. ``record_from`` (s of
log time, default 0: everything) drops the messages logged before it: a
lockstep recording can then start at a given sample with subscriptions that
were matched long before (``maglev-lab``'s closed loop: the first messages on a
freshly matched subscription may be handled after those of other topics, and
would be logged at the previous clock). ``record_until`` (s of log time,
default 0: no end) drops those logged after it: exactly the samples in
between, from a simulation that runs on.

Composed (``intra_process: true``, in one process with the simulator and the
controller): a topic published by a node of this process is taken from its
:func:`~maglev_ros.nodes.intra_process.tap` (the bytes the publisher
serialised, handed over in its thread) instead of a subscription: no
middleware hop, no executor callback per message, which a 5 kHz recording in
a composed real-time loop cannot afford. Messages of other processes on such
a topic are then not recorded; use ``log_clock: stamp`` (a tap hands over a
burst topic by topic).

Metadata (the bag's ``custom_data``): package version, storage, topics,
recording start, and every parameter of ``metadata_node`` (default the
simulator: parameter set, model options, seed, ...) as ``<node>.<name>``,
fetched through its parameter services when it appears. The bag is finalised
(index and ``metadata.yaml``) when the node is destroyed, also after SIGINT,
SIGTERM or SIGHUP and when another signal arrives during that clean-up; the
writer puts the messages into the file every second, so a recorder killed with
SIGKILL leaves a bag that ``maglev-bag2data BAG --reindex`` rebuilds.
"""

from __future__ import annotations

import struct
import threading
import time
from dataclasses import dataclass, replace
from importlib import metadata as importlib_metadata
from pathlib import Path

from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from maglev_ros.bags import BagError, BagWriter
from maglev_ros.nodes import intra_process
from maglev_ros.nodes.params import (
    NodeParameterError,
    Param,
    ParameterTable,
    choice,
    integer,
    number,
)
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.topics import (
    CLOCK_TOPIC,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    TRUE_STATE_TOPIC,
    field_topic,
)

__all__ = [
    'PARAMETERS',
    'DEFAULT_TOPICS',
    'RecorderConfig',
    'RecorderNode',
    'RecorderParameterError',
    'build_config',
    'main',
    'message_class',
]

NODE_NAME = 'maglev_recorder'
DEFAULT_TOPICS = [
    *(field_topic(k) for k in range(3)),
    CURRENTS_TOPIC,
    COMMAND_TOPIC,
    TRUE_STATE_TOPIC,
    CLOCK_TOPIC,
]
_PARAMETER_ANSWER_S = 0.3  # s to wait for one parameter of the metadata node
_CLOCK = struct.Struct('<iI')  # rosgraph_msgs/Clock after the 4-byte CDR header


class RecorderParameterError(NodeParameterError):
    """A recorder parameter has an invalid value."""


@dataclass(frozen=True)
class RecorderConfig:
    """Validated recorder parameters.

    Attributes
    ----------
    path : str
        Bag directory (must not exist).
    storage : str
        ``mcap`` or ``sqlite3``.
    topics : tuple of str
        Fully qualified topic names.
    depth : int
        Subscription queue depth.
    log_clock : str
        ``ros``, ``topic`` or ``stamp``.
    metadata_node : str
        Node whose parameters go into the metadata ('' for none).
    record_from : float
        Log time from which messages are written, s (0: all).
    record_until : float
        Log time after which messages are not written, s (0: no end).
    intra_process : bool
        Take the topics published in this process from their taps.
    """

    path: str
    storage: str
    topics: tuple[str, ...]
    depth: int
    log_clock: str
    metadata_node: str
    record_from: float = 0.0
    record_until: float = 0.0
    intra_process: bool = False


def _topics(name: str, topics: tuple[str, ...]) -> tuple[str, ...]:
    absolute = tuple(dict.fromkeys(_absolute(t) for t in topics if t))
    if not absolute:
        raise RecorderParameterError(f'{name} must name at least one topic, got {list(topics)}')
    return absolute


PARAMETERS = ParameterTable(
    NODE_NAME,
    RecorderParameterError,
    {
        'path': Param(
            '', "bag directory to create; '' : maglev_<date>_<time> in the working directory"
        ),
        'storage': Param('mcap', 'bag storage: mcap or sqlite3', check=choice('mcap', 'sqlite3')),
        'topics': Param(DEFAULT_TOPICS, 'topics to record', check=_topics),
        'depth': Param(10000, 'subscription queue depth (messages)', check=integer(1)),
        'log_clock': Param(
            'ros',
            f'log time: ros (node clock), topic (newest {CLOCK_TOPIC} received) or stamp '
            '(header stamp; header-less messages: the newest stamp recorded)',
            check=choice('ros', 'topic', 'stamp'),
        ),
        'metadata_node': Param('maglev_simulator', "node whose parameters are stored ('' : none)"),
        'record_from': Param(
            0.0,
            'log time from which messages are written, s (0: all; with log_clock topic in '
            'lockstep: a recording that starts at a given sample, its subscriptions already '
            'established)',
            check=number(0),
            mutable=True,
        ),
        'record_until': Param(
            0.0,
            'log time after which messages are not written, s (0: no end)',
            check=number(0),
            mutable=True,
        ),
        'intra_process': Param(
            False,
            'take the topics that nodes of this process publish from them directly, not '
            'through the middleware (composed real-time loops)',
        ),
    },
)
_PARAMETERS = PARAMETERS  # the name test_launch and older callers use


def _absolute(topic: str) -> str:
    return topic if topic.startswith('/') else '/' + topic


def _check_window(v: dict) -> None:
    if v['record_until'] and v['record_until'] < v['record_from']:
        raise RecorderParameterError(
            f'record_until must be 0 (no end) or >= record_from {v["record_from"]:g}, '
            f'got {v["record_until"]:g}'
        )


def build_config(values: dict) -> RecorderConfig:
    """Validate raw parameter values.

    Parameters
    ----------
    values : dict
        Parameter name to value (a missing name takes its default).

    Returns
    -------
    RecorderConfig

    Raises
    ------
    RecorderParameterError
        Naming the first invalid parameter and its value.
    """
    v = PARAMETERS.validate(values)
    if v['log_clock'] == 'topic' and CLOCK_TOPIC not in v['topics']:
        raise RecorderParameterError(
            f'log_clock topic needs {CLOCK_TOPIC} among topics, got {list(v["topics"])}'
        )
    _check_window(v)
    path = v['path'] or time.strftime('maglev_%Y%m%d_%H%M%S')
    if Path(path).exists():
        raise RecorderParameterError(f'path must be a new directory, got {path!r} (exists)')
    return RecorderConfig(**(v | {'path': path}))


def message_class(msgtype: str):
    """Return the rclpy message class of ``pkg/msg/Type``.

    Parameters
    ----------
    msgtype : str
        Message type, ``pkg/msg/Type``.
    """
    import importlib

    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def package_version() -> str:
    """Return the installed maglev_ros version ('unknown' if not installed)."""
    try:
        return importlib_metadata.version('maglev_ros')
    except importlib_metadata.PackageNotFoundError:
        return 'unknown'


def _parameter_value(value):
    kinds = {
        ParameterType.PARAMETER_BOOL: 'bool_value',
        ParameterType.PARAMETER_INTEGER: 'integer_value',
        ParameterType.PARAMETER_DOUBLE: 'double_value',
        ParameterType.PARAMETER_STRING: 'string_value',
    }
    if value.type in kinds:
        return getattr(value, kinds[value.type])
    arrays = {
        ParameterType.PARAMETER_BOOL_ARRAY: 'bool_array_value',
        ParameterType.PARAMETER_INTEGER_ARRAY: 'integer_array_value',
        ParameterType.PARAMETER_DOUBLE_ARRAY: 'double_array_value',
        ParameterType.PARAMETER_STRING_ARRAY: 'string_array_value',
    }
    if value.type in arrays:
        return ' '.join(str(v) for v in getattr(value, arrays[value.type]))
    return ''


class RecorderNode(Node):
    """The bag recorder (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    RecorderParameterError
        If a parameter is invalid.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.config = cfg = build_config(PARAMETERS.declare(self))
        # the window may move at run time (a lab sets it once the settling is over)
        self.add_on_set_parameters_callback(PARAMETERS.on_set(self, self._with_window))
        meta = {
            'maglev_ros.version': package_version(),
            'recorder.storage': cfg.storage,
            'recorder.topics': ' '.join(cfg.topics),
            'recorder.log_clock': cfg.log_clock,
            'recorder.record_from': cfg.record_from,
            'recorder.record_until': cfg.record_until,
            'recorder.intra_process': cfg.intra_process,
            'recorder.started': time.strftime('%Y-%m-%dT%H:%M:%S%z'),
        }
        try:
            self.writer = BagWriter(cfg.path, cfg.storage, metadata=meta)
            self.writer.open()
        except BagError as err:
            raise RecorderParameterError(f'path {cfg.path!r}: {err}') from err
        self.counts = dict.fromkeys(cfg.topics, 0)
        self._handles = {}
        self._taps: list[tuple[object, object]] = []  # (tap, listener): intra_process
        self._write_lock = threading.Lock()  # taps write from their publishers' threads
        self._held: dict[str, tuple[object, bytes]] = {}  # log_clock stamp, before record_from
        # log_clock stamp: the last header-less message written per topic (handle, bytes,
        # log time), the newest stamp taken into the window, and whether the window's
        # end has logged what is in force there (_close_window)
        self._tail: dict[str, tuple[object, bytes, int]] = {}
        self._newest_written = 0
        self._clock_ns = 0
        self._metadata_done = not cfg.metadata_node
        self._metadata_pending = False
        # set while one parameter's request waits for its answer (not while the
        # list of names is still on its way: that answer may come late at start-up)
        self._metadata_skip = None
        self._metadata_items: dict[str, object] = {}  # metadata_node's parameters answered
        self._closed = False
        self.create_timer(0.1, self._discover)
        self._discover()
        self.get_logger().info(
            f'recording {len(cfg.topics)} topic(s) to {cfg.path} ({cfg.storage})'
        )

    @property
    def config(self) -> RecorderConfig:
        """The validated parameters (``record_from``, ``record_until``: settable at run time)."""
        return self._config

    @config.setter
    def config(self, config: RecorderConfig) -> None:
        """Store a validated configuration and its window.

        Parameters
        ----------
        config : RecorderConfig
            The validated parameters.
        """
        self._config = config
        # log times, ns: first and last written (last None: no end)
        self._window = (round(config.record_from * 1e9), round(config.record_until * 1e9) or None)
        self._window_closed = False  # a new window: its end is still to come

    def _with_window(self, values: dict) -> RecorderConfig:
        """Return the configuration with a new window (the only settable parameters)."""
        v = PARAMETERS.validate(values)
        _check_window(v)
        return replace(self.config, record_from=v['record_from'], record_until=v['record_until'])

    @property
    def subscribed(self) -> list[str]:
        """Topics subscribed so far."""
        return list(self._handles)

    @property
    def metadata_complete(self) -> bool:
        """True once the metadata node's parameters are in the bag's metadata."""
        return self._metadata_done

    def _discover(self) -> None:
        if self._closed:
            return
        if self._metadata_done and len(self._handles) == len(self.config.topics):
            return  # all found: no graph query (a few ms of the GIL, 10 times a second)
        types = dict(self.get_topic_names_and_types())
        for topic in self.config.topics:
            if topic in self._handles:
                continue
            tap = None
            if self.config.intra_process:
                tap = intra_process.tap(self.context, self.resolve_topic_name(topic))
            if tap is not None and tap.publishers > 0:  # published in this process
                self._record(topic, tap.msgtype, tap=tap)
                continue
            if not types.get(topic):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            reliable = all(
                p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers
            )
            qos = QoSProfile(
                depth=self.config.depth,
                history=HistoryPolicy.KEEP_LAST,
                reliability=ReliabilityPolicy.RELIABLE
                if reliable
                else ReliabilityPolicy.BEST_EFFORT,
            )
            self._record(topic, types[topic][0], qos=qos)
        if not self._metadata_done and not self._metadata_pending:
            self._request_metadata()
        elif (
            self._metadata_skip is not None
            and time.monotonic() - self._metadata_since > _PARAMETER_ANSWER_S
        ):
            self._metadata_skip()  # no answer (an unset parameter): skip it

    def _record(self, topic: str, msgtype: str, qos=None, tap=None) -> None:
        """Add ``topic`` to the bag; take it from ``tap`` or subscribe with ``qos``."""
        try:
            handle = self.writer.add_topic(topic, msgtype)
            cls = message_class(msgtype)
        except (BagError, ImportError, AttributeError, ValueError) as err:
            self.get_logger().error(f'cannot record {topic} ({msgtype}): {err}')
            self._handles[topic] = None
            return
        self._handles[topic] = handle
        is_clock = topic == CLOCK_TOPIC
        stamped = is_clock or hasattr(cls, 'header')
        write, write_list = self._writer_for(handle, topic, is_clock, stamped)
        if tap is not None:
            listener = write_list
            tap.connect(listener, NODE_NAME)
            self._taps.append((tap, listener))
            self.get_logger().info(f'{topic}: taken in this process (intra_process)')
        else:
            self.create_subscription(cls, topic, write, qos, raw=True)

    def _writer_for(self, handle, topic: str, is_clock: bool, stamped: bool):
        """Return the callbacks that log raw messages of ``topic`` (module docstring).

        Returns
        -------
        on_message : callable
            Logs one message (a subscription's callback).
        on_messages : callable
            Logs a list of them in order, written in one go (a tap's listener).
        """
        write, write_many = self.writer.write, self.writer.write_many
        counts = self.counts
        log_clock = self.config.log_clock
        clock = self.get_clock()
        lock = self._write_lock
        held = self._held

        def log_time(data: bytes) -> int | None:
            """Return the message's log time, ns (None: outside the window, not written)."""
            if is_clock and log_clock == 'topic':
                sec, nanosec = _CLOCK.unpack_from(data, 4)
                self._clock_ns = sec * 1_000_000_000 + nanosec
            if log_clock == 'stamp':
                if stamped:  # the header's stamp (a Clock's time) follows the CDR header
                    sec, nanosec = _CLOCK.unpack_from(data, 4)
                    stamp = sec * 1_000_000_000 + nanosec
                    self._clock_ns = max(self._clock_ns, stamp)
                else:
                    stamp = self._clock_ns
            elif log_clock == 'topic':
                stamp = self._clock_ns
            elif clock.ros_time_is_active:  # use_sim_time: the newest /clock
                stamp = clock.now().nanoseconds
            else:  # system time, as clock.now() gives it, without its Time object (3 us)
                stamp = time.time_ns()
            start_ns, end_ns = self._window
            if stamp < start_ns:
                if log_clock == 'stamp' and not stamped:  # in force when the recording starts
                    held[topic] = (handle, data)
                return None  # before the recording (record_from): not written
            if end_ns is not None and stamp > end_ns:
                if log_clock == 'stamp' and self._tail and not self._window_closed:
                    self._close_window()
                return None  # after it (record_until)
            if held:  # written once the window's first sample is complete
                if not stamped and stamp == start_ns:
                    held.pop(topic, None)  # superseded at the window's first sample
                elif stamp > start_ns:
                    self._write_held(start_ns)
            if stamped and stamp > self._newest_written:
                self._newest_written = stamp  # the newest sample in the window
            return stamp

        track = log_clock == 'stamp'  # what is in force at the window's end (_close_window)

        def written(stamp: int, data: bytes) -> None:
            if not stamped:
                self._tail[topic] = (handle, data, stamp)

        def on_message(data: bytes) -> None:
            stamp = log_time(data)
            if stamp is None:
                return
            with lock:
                try:
                    write(handle, stamp, data)
                except BagError:  # closed while this message was in flight
                    return
                counts[topic] += 1
                if track:
                    written(stamp, data)

        def on_messages(messages: list) -> None:
            stamps, kept = [], []
            for data in messages:
                stamp = log_time(data)
                if stamp is not None:
                    stamps.append(stamp)
                    kept.append(data)
            if not kept:
                return
            with lock:
                try:
                    write_many(handle, stamps, kept)
                except BagError:  # closed while these messages were in flight
                    return
                counts[topic] += len(kept)
                if track:
                    written(stamps[-1], kept[-1])

        return on_message, on_messages

    def _close_window(self) -> None:
        """Log the header-less messages in force at the window's last sample at its stamp.

        ``log_clock: stamp`` with ``record_until``: a command logged before the
        window's last sample is still in force there; the bag converter holds an
        input for one of its own periods after its last message, so the window's
        last samples would be trimmed. Logged once more at the last sample
        written, they are not. The mirror of the start's rule
        (:meth:`_write_held`).
        """
        with self._write_lock:
            if self._window_closed:
                return
            self._window_closed = True
            newest = self._newest_written
            for topic, (handle, data, stamp) in list(self._tail.items()):
                if stamp >= newest:
                    continue  # already logged at the last sample
                try:
                    self.writer.write(handle, newest, data)
                except BagError:
                    return
                self.counts[topic] += 1

    def _write_held(self, stamp: int) -> None:
        """Log the header-less messages held from before ``record_from`` at its ``stamp``.

        ``log_clock: stamp``: the newest command (and any header-less message)
        before the recording is the one in force at its first sample; the bag
        converter holds inputs from their log time, so it is written at the
        recording's start rather than lost.
        """
        with self._write_lock:
            held = list(self._held.items())
            self._held.clear()  # the same dict the callbacks hold
            for topic, (handle, data) in held:
                try:
                    self.writer.write(handle, stamp, data)
                except BagError:
                    return
                self.counts[topic] += 1

    def _request_metadata(self) -> None:
        name = self.config.metadata_node
        nodes = {n for n, _ in self.get_node_names_and_namespaces()}
        if name not in nodes:
            return
        self._metadata_pending = True
        prefix = f'/{name}'
        lister = self.create_client(ListParameters, f'{prefix}/list_parameters')
        getter = self.create_client(GetParameters, f'{prefix}/get_parameters')
        if not (lister.service_is_ready() and getter.service_is_ready()):
            self.destroy_client(lister)
            self.destroy_client(getter)
            self._metadata_pending = False
            return

        items = self._metadata_items  # kept: a bag closed before the last answer gets these
        self._metadata_since = time.monotonic()

        def ask(names):
            # one parameter per request, one request at a time: a node answers
            # nothing for an unset (typed, no default) parameter
            if not names:
                if not self._closed and not self._metadata_done:
                    self.writer.set_metadata(items)
                self._metadata_done = True
                self._metadata_pending = False
                self._metadata_skip = None
                return
            parameter = names[0]
            self._metadata_since = time.monotonic()
            self._metadata_skip = lambda: ask(names[1:])
            token = self._metadata_since

            def got_value(future):
                if token != self._metadata_since:
                    return  # skipped after the timeout
                result = future.result()
                if result is not None and result.values:
                    items[f'{name}.{parameter}'] = _parameter_value(result.values[0])
                ask(names[1:])

            getter.call_async(GetParameters.Request(names=[parameter])).add_done_callback(
                got_value
            )

        def got_names(future):
            result = future.result()
            if result is None or not result.result.names:
                self._metadata_pending = False
                return
            ask(list(result.result.names))

        lister.call_async(ListParameters.Request()).add_done_callback(got_names)

    def close(self) -> None:
        """Finalise the bag (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for tap, listener in self._taps:
            tap.disconnect(listener)
        self._taps = []
        if self._held and any(self.counts.values()):  # a window of a single sample
            self._write_held(self._window[0])
        if self._window[1] is not None and self._tail:  # the window's end never came
            self._close_window()
        if not self._metadata_done and self._metadata_items:
            # stopped while the metadata node's parameters were still being asked for:
            # the answers so far are stored (a partial set beats none)
            self.writer.set_metadata(dict(self._metadata_items))
            self._metadata_done = True
        with self._write_lock:  # a tap's listener may be writing in its publisher's thread
            self.writer.close()
        total = sum(self.counts.values())
        self.get_logger().info(f'bag {self.config.path} closed: {total} messages')

    def destroy_node(self) -> None:
        """Finalise the bag, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Record until SIGINT, SIGTERM or SIGHUP; the bag is finalised either way.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return run_nodes([RecorderNode], args, NODE_NAME, (RecorderParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
