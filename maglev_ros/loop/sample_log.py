"""Keep a loop's samples in memory and write them as a bag afterwards.

A real-time loop on a board does no file work in its period: :class:`SampleLog`
(an observer of :class:`~maglev_ros.loop.ControlLoop`) appends each sample's
numbers to lists, and :func:`write_sample_bag` writes the bag once the run
is over, in the topics and types of ``docs/topics.md``:

* ``maglev/sensor_<k>/field`` (sensor_msgs/MagneticField, T): the readings;
* ``maglev/currents`` (sensor_msgs/JointState, effort A, x+ x- y+ y-): the
  currents measured at the sample;
* ``maglev/currents/command`` and ``maglev/currents/excitation``
  (sensor_msgs/JointState, effort A): the command written after the sample
  and its excitation part, stamped with the sample they answer;
* ``maglev/state/estimate`` (nav_msgs/Odometry): the estimator's state.

Every message carries the sample's stamp, and its log time is that stamp.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..topics import (
    COIL_NAMES,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    ESTIMATE_TOPIC,
    EXCITATION_TOPIC,
    FIELD_MESSAGE_TYPE,
    field_topic,
    sensor_frame,
)

__all__ = ['SampleLog', 'write_sample_bag']

_JOINT_STATE = 'sensor_msgs/msg/JointState'


class SampleLog:
    """Observer keeping every sample's stamp, reading, currents, command and estimate.

    Parameters
    ----------
    applied : callable, optional
        ``applied(command) -> currents``: what the plant really applies for a
        command (a board's guard: pairs, clamp, PWM steps); default the command.
    first : int, optional
        Samples with a smaller index are not kept (a settling time before the
        record).
    """

    def __init__(self, applied=None, first: int = 0) -> None:
        self.applied_of = applied
        self.first = int(first)
        self.skipped = 0
        self.index: list[int] = []
        self.stamps_ns: list[int] = []
        self.readings: list[np.ndarray] = []
        self.currents: list[np.ndarray] = []
        self.commands: list[np.ndarray] = []
        self.excitation: list[np.ndarray] = []
        self.estimates: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self.index)

    def __call__(self, s) -> None:
        """Keep one :class:`~maglev_ros.loop.LoopSample` (not a period without readings)."""
        if s.index < self.first:
            return
        if not np.isfinite(s.reading).any():
            self.skipped += 1  # a period the host missed: a gap in the bag
            return
        n_s = s.currents.shape[0]
        applied = np.zeros(n_s) if s.applied is None else s.applied
        if self.applied_of is not None:
            applied = self.applied_of(applied)
        self.index.append(s.index)
        self.stamps_ns.append(s.stamp_ns)
        self.readings.append(np.array(s.reading, dtype=float))
        self.currents.append(np.array(s.currents, dtype=float))
        self.commands.append(np.array(applied, dtype=float))
        self.excitation.append(np.zeros(n_s) if s.excitation is None else s.excitation)
        self.estimates.append(np.full(12, np.nan) if s.estimate is None else s.estimate)

    def arrays(self) -> dict[str, np.ndarray]:
        """Return the kept samples as arrays (n rows each)."""
        return {
            'index': np.array(self.index, dtype=np.int64),
            'stamps_ns': np.array(self.stamps_ns, dtype=np.int64),
            'readings': np.array(self.readings).reshape(len(self), -1),
            'currents': np.array(self.currents).reshape(len(self), -1),
            'commands': np.array(self.commands).reshape(len(self), -1),
            'excitation': np.array(self.excitation).reshape(len(self), -1),
            'estimates': np.array(self.estimates).reshape(len(self), 12),
        }


def write_sample_bag(
    path: str | Path,
    log: SampleLog,
    sensors: Sequence[int] = (0,),
    metadata: Mapping[str, object] | None = None,
) -> Path:
    """Write the samples of ``log`` as a bag (MCAP) at ``path``.

    Parameters
    ----------
    path : str or Path
        New bag directory.
    log : SampleLog
        The samples.
    sensors : sequence of int
        The parameter set's index of each sensor of the readings (a V4x
        board: the one sensor it reads).
    metadata : mapping, optional
        Run metadata (``magnet``, ``params``, ``firmware``, ...).

    Returns
    -------
    Path
        The bag directory.
    """
    from ..bags.writer import BagWriter
    from ..cdr.batch import RawMessageBatch
    from ..cdr.templates import currents_layout, estimate_layout, field_layout
    from ..physics.kernels import odometry_values

    a = log.arrays()
    stamps = a['stamps_ns']
    n = stamps.shape[0]
    odometry = np.zeros((n, 85))  # covariances not kept: zero (unknown, REP 147 style)
    for i, x in enumerate(a['estimates']):
        odometry[i, :13] = odometry_values(x)
    with BagWriter(path, metadata=metadata) as bag:
        for j, k in enumerate(sensors):
            topic = bag.add_topic(field_topic(k), FIELD_MESSAGE_TYPE)
            batch = RawMessageBatch(field_layout(sensor_frame(k)))
            bag.write_many(
                topic, stamps, batch.serialise(stamps, a['readings'][:, 3 * j : 3 * j + 3])
            )
        batch = RawMessageBatch(currents_layout(COIL_NAMES))
        for name, key in (
            (CURRENTS_TOPIC, 'currents'),
            (COMMAND_TOPIC, 'commands'),
            (EXCITATION_TOPIC, 'excitation'),
        ):
            topic = bag.add_topic(name, _JOINT_STATE)
            bag.write_many(topic, stamps, batch.serialise(stamps, a[key]))
        topic = bag.add_topic(ESTIMATE_TOPIC, 'nav_msgs/msg/Odometry')
        bag.write_many(
            topic, stamps, RawMessageBatch(estimate_layout()).serialise(stamps, odometry)
        )
    return Path(path)
