"""Publish the control loop's samples for observers, never holding the loop up.

The loop hands a sample to :class:`LoopBroadcaster` (an
:class:`~maglev_ros.loop.ObserverThread`: a bounded queue, dropped and counted
when full) and the broadcaster's thread serialises and publishes it on the
topics of ``docs/topics.md``: each sensor's field, the currents, the true
state (simulated plants), the estimate, the command and ``/clock``. A topic
nobody subscribes to is not published.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.loop import LoopSample, ObserverThread
from maglev_ros.nodes.messages import command_message, split_stamp
from maglev_ros.nodes.qos import SENSOR_QOS
from maglev_ros.nodes.state_messages import EstimateEncoder
from maglev_ros.physics.sample_encoder import SampleEncoder
from maglev_ros.topics import CLOCK_TOPIC, COMMAND_TOPIC, ESTIMATE_TOPIC, field_topic

__all__ = ['LoopBroadcaster', 'LoopEncoder']

#: Samples a broadcaster may hold before it drops (0.5 s at 1 kHz).
DEPTH = 500
#: Samples between checks of who subscribes.
MATCH_EVERY = 200


@dataclass(frozen=True)
class _Batch:
    """One sample in the shape :class:`~maglev_ros.physics.sample_encoder.SampleEncoder` takes."""

    indices: np.ndarray
    stamps_ns: np.ndarray
    readings: np.ndarray
    states: np.ndarray
    currents: np.ndarray

    def __len__(self) -> int:
        return 1


class LoopEncoder:
    """The messages of one loop sample, as :class:`LoopBroadcaster` publishes them.

    Serialises without a node, so the kernels it uses can be compiled ahead
    (``maglev_ros.cli.kernels``).

    Parameters
    ----------
    sensors : int
        Sensors of the plant.
    true_state : bool
        Encode ``maglev/state/true`` too.
    """

    def __init__(self, sensors: int, true_state: bool) -> None:
        self._samples = SampleEncoder(range(sensors), state=true_state, clock='none')
        self.topics = self._samples.topics
        self._estimates = EstimateEncoder()
        self._estimates.encode(0, np.zeros(12), np.eye(10))  # its kernel loads now, not later
        self._clock = Clock()

    def sample(self, s: LoopSample) -> list:
        """Return the field, currents (and true state) messages of ``s``, as ``topics``.

        Parameters
        ----------
        s : LoopSample
            The loop's sample.
        """
        batch = _Batch(
            np.array([s.index]),
            np.array([s.stamp_ns], dtype=np.int64),
            s.reading[None, :],
            np.zeros((1, 12)) if s.state is None else s.state[None, :],
            s.currents[None, :],
        )
        return self._samples.sample_messages(batch)

    def estimate(self, s: LoopSample) -> bytes:
        """Return the serialised ``maglev/state/estimate`` of ``s`` (it has an estimate).

        Parameters
        ----------
        s : LoopSample
            The loop's sample.
        """
        return self._estimates.encode(s.stamp_ns, s.estimate, s.covariance)

    def command(self, s: LoopSample) -> JointState:
        """Return the command ``s`` answered with (excitation included).

        Parameters
        ----------
        s : LoopSample
            The loop's sample.
        """
        total = s.command if s.excitation is None else s.command + s.excitation
        return command_message(s.stamp_ns, total)

    def clock(self, s: LoopSample) -> Clock:
        """Return ``/clock`` at ``s`` (one message, reused).

        Parameters
        ----------
        s : LoopSample
            The loop's sample.
        """
        self._clock.clock.sec, self._clock.clock.nanosec = split_stamp(s.stamp_ns)
        return self._clock


class LoopBroadcaster(ObserverThread):
    """Publishes loop samples on the node's topics from a thread of its own.

    Parameters
    ----------
    node : rclpy.node.Node
        Owns the publishers.
    sensors : int
        Sensors of the plant (each gets its field topic).
    true_state : bool
        Publish ``maglev/state/true`` (a simulated plant knows it).
    """

    def __init__(self, node, sensors: int, true_state: bool) -> None:
        from nav_msgs.msg import Odometry

        from maglev_ros.topics import CURRENTS_TOPIC, TRUE_STATE_TOPIC

        self._encode = LoopEncoder(sensors, true_state)
        types = {CURRENTS_TOPIC: JointState, TRUE_STATE_TOPIC: Odometry}
        types.update({field_topic(k): MagneticField for k in range(sensors)})
        self._sample_pubs = [
            node.create_publisher(types[t], t, SENSOR_QOS) for t in self._encode.topics
        ]
        self._estimate_pub = node.create_publisher(Odometry, ESTIMATE_TOPIC, SENSOR_QOS)
        self._command_pub = node.create_publisher(JointState, COMMAND_TOPIC, SENSOR_QOS)
        self._clock_pub = node.create_publisher(Clock, CLOCK_TOPIC, SENSOR_QOS)
        self._wanted = [True] * (len(self._sample_pubs) + 3)
        self._count = 0
        self.published = 0
        super().__init__(self._publish, DEPTH, name='maglev-broadcast')

    def _publish(self, s: LoopSample) -> None:
        if self._count % MATCH_EVERY == 0:
            pubs = [*self._sample_pubs, self._estimate_pub, self._command_pub, self._clock_pub]
            self._wanted = [p.get_subscription_count() > 0 for p in pubs]
        self._count += 1
        wanted = self._wanted
        n = len(self._sample_pubs)
        if any(wanted[:n]):
            messages = self._encode.sample(s)
            for pub, data, on in zip(self._sample_pubs, messages, wanted[:n], strict=True):
                if on:
                    pub.publish(data)
        if wanted[n] and s.estimate is not None:
            self._estimate_pub.publish(self._encode.estimate(s))
        if wanted[n + 1] and s.command is not None:
            self._command_pub.publish(self._encode.command(s))
        if wanted[n + 2]:
            self._clock_pub.publish(self._encode.clock(s))
        self.published += 1
