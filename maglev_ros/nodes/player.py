"""Player node: ``ros2 run maglev_ros player`` - republish a bag, with its clock.

For pip-only machines (``ros2 bag play`` needs a ROS installation). Reads a
rosbag2 directory (MCAP or sqlite3) with rosbags and republishes the stored
CDR bytes unchanged on their topics, paced by the log times at ``rate`` x
real time (0: as fast as possible), optionally in a loop. ``/clock`` is
published from the log times (every ``clock_period`` s of bag time, and
before every message), unless the bag has its own ``/clock`` topic, which is
then played like any other. QoS: RELIABLE, KEEP_LAST 1000 for every topic
(matches reliable and best-effort subscribers).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from rclpy.node import Node
from rosbags.rosbag2 import Reader
from rosgraph_msgs.msg import Clock

from maglev_ros.nodes import contract
from maglev_ros.nodes.params import NodeParameterError, Param, ParameterTable, number
from maglev_ros.nodes.recorder import message_class

__all__ = ['PARAMETERS', 'PlayerNode', 'PlayerParameterError', 'main']

NODE_NAME = 'maglev_player'


class PlayerParameterError(NodeParameterError):
    """A player parameter has an invalid value."""


def _existing(name: str, path: str) -> str:
    if not path or not Path(path).exists():
        raise PlayerParameterError(f'{name} must be an existing bag, got {path!r}')
    return path


PARAMETERS = ParameterTable(
    NODE_NAME,
    PlayerParameterError,
    {
        'path': Param('', 'bag directory to play', check=_existing),
        'rate': Param(
            1.0, 'playback speed, x real time (0: as fast as possible)', check=number(0)
        ),
        'loop': Param(False, 'start again at the end'),
        'topics': Param(['*'], "topics to play ('*': all)"),
        'clock_period': Param(
            0.01,
            f's of bag time between {contract.CLOCK_TOPIC} messages (bags without one)',
            check=number(0),
        ),
        'start_delay': Param(
            0.5, 's to wait before playing (lets subscribers connect)', check=number(0)
        ),
    },
)
_PARAMETERS = PARAMETERS  # the name test_launch and older callers use


class PlayerNode(Node):
    """The bag player (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    PlayerParameterError
        If a parameter is invalid or the bag cannot be opened.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        v = PARAMETERS.validate(PARAMETERS.declare(self))
        self.rate = v['rate']
        self.loop = v['loop']
        self.clock_period_ns = int(v['clock_period'] * 1e9)
        self.start_delay = v['start_delay']
        self.path = v['path']
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as err:  # noqa: BLE001 - rosbags raises several kinds
            raise PlayerParameterError(f'path {v["path"]!r}: not a readable bag ({err})') from err
        wanted = set(v['topics'])
        everything = '*' in wanted
        wanted = {t if t.startswith('/') else '/' + t for t in wanted}
        self._connections = [
            c for c in self._reader.connections if everything or c.topic in wanted
        ]
        self._topic_pubs = {}
        for conn in self._connections:
            if conn.topic not in self._topic_pubs:
                self._topic_pubs[conn.topic] = self.create_publisher(
                    message_class(conn.msgtype), conn.topic, contract.SENSOR_QOS
                )
        self._own_clock = contract.CLOCK_TOPIC not in self._topic_pubs
        self._clock_pub = (
            self.create_publisher(Clock, contract.CLOCK_TOPIC, contract.SENSOR_QOS)
            if self._own_clock
            else None
        )
        self._clock_raw = contract.clock_template()
        self.published = 0
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._play, name='maglev-player', daemon=True)
        self._thread.start()
        self.get_logger().info(
            f'playing {self.path}: {len(self._topic_pubs)} topic(s) at {self.rate:g} x'
        )

    def _play(self) -> None:
        if self._stop.wait(self.start_delay):
            return
        try:
            while not self._stop.is_set():
                self._play_once()
                if not self.loop:
                    break
        except Exception as err:  # noqa: BLE001 - context shut down mid-publish
            if self.context.ok() and not self._stop.is_set():
                self.get_logger().error(f'playback failed: {err}')
        self.done.set()

    def _play_once(self) -> None:
        wall0 = None
        next_clock = None
        for conn, t_ns, data in self._reader.messages(connections=self._connections):
            if self._stop.is_set():
                return
            if wall0 is None:
                wall0, bag0 = time.monotonic(), t_ns
            if self.rate > 0:
                delay = wall0 + (t_ns - bag0) * 1e-9 / self.rate - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    return
            if self._own_clock and (next_clock is None or t_ns >= next_clock):
                self._clock_pub.publish(self._clock_raw.serialise(t_ns))
                next_clock = t_ns + self.clock_period_ns
            self._topic_pubs[conn.topic].publish(bytes(data))
            self.published += 1

    def close(self) -> None:
        """Stop playing and close the bag (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._reader.close()

    def destroy_node(self) -> None:
        """Stop playing, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Play until the end of the bag (unless looping), SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return contract.run_nodes([PlayerNode], args, NODE_NAME, (PlayerParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
