"""An observer of the lab session that writes its recorded samples into a bag, ROS-free.

The topics of a lab bag (``docs/topics.md``), each message logged at the
stamp of the sample it belongs to:

* ``maglev/sensor_<k>/field`` (MagneticField, T) of each recorded sensor and
  ``maglev/currents`` (JointState, A), every sample;
* ``maglev/currents/command`` and ``maglev/currents/excitation``: the command
  that drives the coils from the sample on and its excitation part, A, one
  message per command written (every sample in lockstep, one per control
  period in real time; the window's first sample carries the one in force).
  The message type is the contract's (:data:`maglev_ros.topics.MESSAGE_TYPES`):
  a stamped ``sensor_msgs/JointState`` (names ``x+ x- y+ y-``, ``effort``,
  ``header.stamp`` = the sample's) or the older ``std_msgs/Float64MultiArray``;
* ``maglev/state/true`` (Odometry) and ``/clock`` of a simulation, every sample.

Messages are serialised in batches by the compiled template writer
(:mod:`maglev_ros.cdr.batch`) and written per topic
(:meth:`~maglev_ros.bags.BagWriter.write_many`): a few microseconds a sample.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Mapping, Sequence
from importlib import metadata as importlib_metadata
from pathlib import Path

import numpy as np

from ..bags.writer import BagWriter
from ..cdr.batch import RawMessageBatch, SampleSerialiser
from ..cdr.templates import (
    clock_layout,
    currents_layout,
    field_layout,
    float_array_prefix,
    odometry_layout,
)
from ..physics.kernels import odometry_values
from ..topics import (
    CLOCK_TOPIC,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    EXCITATION_TOPIC,
    FIELD_MESSAGE_TYPE,
    MESSAGE_TYPES,
    TRUE_STATE_TOPIC,
    field_topic,
    sensor_frame,
)
from .session import WindowSample

__all__ = ['BagRecorder', 'package_version']

JOINT_STATE = 'sensor_msgs/msg/JointState'


def package_version() -> str:
    """Return the installed maglev_ros version ('unknown' if not installed)."""
    try:
        return importlib_metadata.version('maglev_ros')
    except importlib_metadata.PackageNotFoundError:
        return 'unknown'


class BagRecorder:
    """Write recorded samples (:class:`~maglev_ros.loop.WindowSample`) into a new bag.

    Parameters
    ----------
    path : str or Path
        Bag directory to create (it must not exist).
    sensors : sequence of int
        Sensors whose fields are written (columns ``3 k .. 3 k + 2`` of a reading).
    storage : {'mcap', 'sqlite3'}
        Storage plugin.
    metadata : mapping, optional
        Flat run metadata (the plant's settings, ...), stored in the bag.
    true_state : bool
        Write ``maglev/state/true`` (a simulation's samples carry it).
    clock : bool
        Write ``/clock`` with every sample (a simulation's time).
    batch : int
        Samples serialised and written at once.

    Attributes
    ----------
    counts : dict of str to int
        Messages written per topic.
    """

    def __init__(
        self,
        path: str | Path,
        sensors: Sequence[int] = (0,),
        storage: str = 'mcap',
        metadata: Mapping[str, object] | None = None,
        true_state: bool = True,
        clock: bool = True,
        batch: int = 500,
    ) -> None:
        self.sensors = tuple(int(k) for k in sensors)
        self.true_state = bool(true_state)
        self.clock = bool(clock)
        self.batch = int(batch)
        self._columns = np.array([3 * k + a for k in self.sensors for a in range(3)])
        sample_topics = [field_topic(k) for k in self.sensors]
        layouts = [field_layout(sensor_frame(k)) for k in self.sensors]
        if self.true_state:
            sample_topics.append(TRUE_STATE_TOPIC)
            layouts.append(odometry_layout())
        sample_topics.append(CURRENTS_TOPIC)
        layouts.append(currents_layout())
        if self.clock:
            sample_topics.append(CLOCK_TOPIC)
            layouts.append(clock_layout())
        self._sample_topics = sample_topics
        self._samples = SampleSerialiser([RawMessageBatch(x) for x in layouts])
        self.command_type = MESSAGE_TYPES[COMMAND_TOPIC]
        self._commands = SampleSerialiser([RawMessageBatch(currents_layout())])
        self._prefix = float_array_prefix(4)
        types = {t: FIELD_MESSAGE_TYPE for t in sample_topics[: len(self.sensors)]}
        types.update({t: MESSAGE_TYPES[t] for t in sample_topics[len(self.sensors) :]})
        types[COMMAND_TOPIC] = self.command_type
        types[EXCITATION_TOPIC] = MESSAGE_TYPES[EXCITATION_TOPIC]
        meta = {
            'maglev_ros.version': package_version(),
            'recorder.storage': storage,
            'recorder.topics': ' '.join(types),
            'recorder.log_clock': 'stamp',
            'recorder.started': time.strftime('%Y-%m-%dT%H:%M:%S%z'),
            **dict(metadata or {}),
        }
        self._types = types
        self.writer = BagWriter(path, storage, metadata=meta).open()
        self._handles = {t: self.writer.add_topic(t, m) for t, m in types.items()}
        self.counts = dict.fromkeys(types, 0)
        self._pending: list[WindowSample] = []
        self._closed = False
        # the compiled kernels load now (up to 1 s holding the GIL), not in a real-time run
        self._samples.serialise(np.zeros(1, np.int64), np.zeros((1, self._samples.n_values)))
        self._commands.serialise(np.zeros(1, np.int64), np.zeros((1, 4)))
        odometry_values(np.zeros(12))

    def __call__(self, item: WindowSample) -> None:
        """Take one recorded sample (written with the next batch)."""
        self._pending.append(item)
        if len(self._pending) >= self.batch:
            self.flush()

    def flush(self) -> None:
        """Write the samples taken so far."""
        items, self._pending = self._pending, []
        if not items or self._closed:
            return
        samples = [w.sample for w in items]
        stamps = np.fromiter((s.stamp_ns for s in samples), np.int64, len(samples))
        values = [np.array([s.reading for s in samples])[:, self._columns]]
        if self.true_state:
            values.append(np.array([odometry_values(s.state) for s in samples]))
        values.append(np.array([s.currents for s in samples]))
        if self.clock:
            values.append(np.zeros((len(samples), 0)))
        messages = self._samples.serialise(stamps, values)
        k = len(self._sample_topics)
        for i, topic in enumerate(self._sample_topics):
            self._write(topic, stamps, messages[i::k])
        commanded = [
            (w.sample.stamp_ns, w.command, w.excitation) for w in items if w.command is not None
        ]
        if commanded:
            at = np.array([c[0] for c in commanded], dtype=np.int64)
            for topic, column in ((COMMAND_TOPIC, 1), (EXCITATION_TOPIC, 2)):
                rows = np.array([c[column] for c in commanded], dtype=float)
                self._write(topic, at, self._command_messages(topic, at, rows))

    def _command_messages(self, topic: str, stamps: np.ndarray, rows: np.ndarray) -> list[bytes]:
        if self._types[topic] == JOINT_STATE:
            return self._commands.serialise(stamps, rows)
        pack = struct.Struct(f'<{rows.shape[1]}d').pack
        return [self._prefix + pack(*row) for row in rows.tolist()]

    def _write(self, topic: str, stamps: np.ndarray, messages: list[bytes]) -> None:
        self.writer.write_many(self._handles[topic], stamps.tolist(), messages)
        self.counts[topic] += len(messages)

    def set_metadata(self, metadata: Mapping[str, object]) -> None:
        """Add run metadata (e.g. how the run ended) before :meth:`close`.

        Parameters
        ----------
        metadata : mapping
            Flat items.
        """
        self.writer.set_metadata(metadata)

    def close(self) -> None:
        """Write what is pending and finalise the bag (idempotent)."""
        if self._closed:
            return
        try:
            self.flush()
        finally:
            self._closed = True
            self.writer.close()
