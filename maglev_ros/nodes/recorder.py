"""Recorder node: ``ros2 run maglev_ros recorder``.

Writes chosen topics to a rosbag2 directory (MCAP, or sqlite3) with rosbags, as
received (``raw=True``: the CDR bytes). A topic is subscribed once its type is in
the graph: RELIABLE if every publisher is, else BEST_EFFORT, with depth ``depth``.
Log times (``log_clock``) and the window (``record_from``, ``record_until``,
settable at run time) are :class:`maglev_ros.bags.recording.Recording`'s: with
``stamp`` a message is logged at its header stamp, so the commands (JointState,
stamped with the sample they answer) align with their samples; the command in
force at the window's start (and end) is kept there.

Metadata (the bag's ``custom_data``): version, storage, topics, start, and every
parameter of ``metadata_node`` as ``<node>.<name>``. The bag is finalised when the
node is destroyed (also after SIGINT, SIGTERM, SIGHUP); after SIGKILL,
``maglev-bag2data BAG --reindex`` rebuilds it.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import replace
from functools import partial
from pathlib import Path

from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from maglev_ros.bags import BagError, BagWriter
from maglev_ros.bags.names import normalize_topic
from maglev_ros.bags.recording import Recording, RecordingConfig
from maglev_ros.nodes.params import (
    NodeParameterError,
    Param,
    ParameterTable,
    choice,
    integer,
    number,
)
from maglev_ros.nodes.remote_parameters import RemoteParameters
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
    'REMOVED',
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
#: Parameters the recorder no longer has, and what replaced them.
REMOVED = {
    'intra_process': 'the recorder subscribes to every topic; a composed loop process '
    'publishes its topics for it',
}


class RecorderParameterError(NodeParameterError):
    """A recorder parameter has an invalid value."""


RecorderConfig = RecordingConfig  # the validated parameters


def _topics(name: str, topics: tuple[str, ...]) -> tuple[str, ...]:
    absolute = tuple(dict.fromkeys(normalize_topic(t) for t in topics if t))
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
            'log time from which messages are written, s (0: all; the command in force '
            'there is written at it)',
            check=number(0),
            mutable=True,
        ),
        'record_until': Param(
            0.0,
            'log time after which messages are not written, s (0: no end)',
            check=number(0),
            mutable=True,
        ),
    },
    removed=REMOVED,
)
_PARAMETERS = PARAMETERS  # the name test_launch and older callers use


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
    """Return the rclpy message class of a message type.

    Parameters
    ----------
    msgtype : str
        ``pkg/msg/Type``.
    """
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


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
        self.add_on_set_parameters_callback(PARAMETERS.on_set(self, self._with_window))
        try:
            self.writer = BagWriter(cfg.path, cfg.storage, metadata=cfg.metadata()).open()
        except BagError as err:
            raise RecorderParameterError(f'path {cfg.path!r}: {err}') from err
        self.recording = Recording(self.writer, cfg.log_clock, self._now, *cfg.window_ns)
        self.counts = self.recording.counts  # messages written per topic, 0 until it appears
        self.counts.update(dict.fromkeys(cfg.topics, 0))
        self._handled: set[str] = set()  # topics subscribed (or refused by the bag)
        self.metadata = RemoteParameters(self, cfg.metadata_node, self._store_metadata)
        self.metadata.done = not cfg.metadata_node
        self.create_timer(0.1, self._discover)
        self._discover()
        self.get_logger().info(
            f'recording {len(cfg.topics)} topic(s) to {cfg.path} ({cfg.storage})'
        )

    def _now(self) -> int:
        """Return the node's time, ns (use_sim_time: /clock; else wall time, no Time object)."""
        clock = self.get_clock()
        return clock.now().nanoseconds if clock.ros_time_is_active else time.time_ns()

    def _with_window(self, values: dict) -> RecorderConfig:
        """Check a new window (the only settable parameters), move the recording's to it."""
        v = PARAMETERS.validate(values)
        _check_window(v)
        config = replace(self.config, record_from=v['record_from'], record_until=v['record_until'])
        self.recording.set_window(*config.window_ns)
        return config  # stored as self.config by the parameter table

    @property
    def subscribed(self) -> list[str]:
        """Topics subscribed so far."""
        return list(self._handled)

    @property
    def metadata_complete(self) -> bool:
        """True once the metadata node's parameters are in the bag's metadata."""
        return self.metadata.done

    def _discover(self) -> None:
        if self.recording.closed:
            return
        self.metadata.poll()
        if len(self._handled) == len(self.config.topics):
            return  # all found: no graph query (a few ms of the GIL, 10 times a second)
        types = dict(self.get_topic_names_and_types())
        for topic in self.config.topics:
            publishers = self.get_publishers_info_by_topic(topic) if types.get(topic) else []
            if topic in self._handled or not publishers:
                continue
            self._handled.add(topic)
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
            msgtype = types[topic][0]
            try:
                cls = message_class(msgtype)
                self.recording.add_topic(topic, msgtype, stamped=hasattr(cls, 'header'))
            except (BagError, ImportError, AttributeError, ValueError) as err:
                self.get_logger().error(f'cannot record {topic} ({msgtype}): {err}')
                continue
            self.create_subscription(
                cls, topic, partial(self.recording.write, topic), qos, raw=True
            )

    def _store_metadata(self, items: dict) -> None:
        if not self.recording.closed:
            self.writer.set_metadata(items)

    def close(self) -> None:
        """Finalise the bag (idempotent): the metadata answered so far goes in too."""
        if self.recording.closed:
            return
        if not self.metadata.done and self.metadata.items:
            self.writer.set_metadata(dict(self.metadata.items))  # a partial set beats none
            self.metadata.done = True
        self.recording.close()
        self.get_logger().info(f'bag {self.config.path} closed: {self.recording.total} messages')

    def destroy_node(self) -> None:
        """Finalise the bag, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Record until SIGINT, SIGTERM or SIGHUP; the bag is finalised either way.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS ones included); exit status 2 for bad parameters.
    """
    return run_nodes([RecorderNode], args, NODE_NAME, (RecorderParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
