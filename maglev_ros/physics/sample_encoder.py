"""The simulator's samples as CDR messages, ROS-free.

:class:`SampleEncoder` turns a :class:`~maglev_ros.physics.session.SampleBatch`
into the serialised messages the simulator node publishes, in publishing
order, with the compiled burst serialiser of :mod:`maglev_ros.cdr.batch`.
Per sample: ``/clock`` when it goes with every sample (lockstep), the field of
each published sensor, the true state, the currents (last: the currents mark
a complete sample). ``/clock`` once per burst (real time) comes separately.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

from ..cdr import clock_layout, currents_layout, field_layout, odometry_layout
from ..cdr.batch import RawMessageBatch, SampleSerialiser
from ..topics import CLOCK_TOPIC, CURRENTS_TOPIC, TRUE_STATE_TOPIC, field_topic, sensor_frame
from .kernels import odometry_values
from .session import SampleBatch

__all__ = ['CLOCK_MODES', 'SampleEncoder']

#: ``/clock``: not published, with every sample, or once per burst.
CLOCK_MODES = ('none', 'sample', 'burst')


class SampleEncoder:
    """Serialise batches of simulated samples into their messages.

    Parameters
    ----------
    sensors : sequence of int
        Indices of the published sensors (their readings' columns 3k .. 3k+2).
    state : bool
        Publish the true state (Odometry).
    clock : {'none', 'sample', 'burst'}
        ``/clock`` with none, every sample, or each sample whose index is a
        multiple of ``burst``.
    burst : int, optional
        Samples per real-time burst (``clock='burst'``).

    Attributes
    ----------
    topics : tuple of str
        The topic of each message of one sample, in publishing order.
    """

    def __init__(self, sensors: Sequence[int], state: bool, clock: str, burst: int = 1) -> None:
        if clock not in CLOCK_MODES:
            raise ValueError(f'clock must be one of {", ".join(CLOCK_MODES)}, got {clock!r}')
        layouts = [field_layout(sensor_frame(k)) for k in sensors]
        topics = [field_topic(k) for k in sensors]
        if state:
            layouts.append(odometry_layout())
            topics.append(TRUE_STATE_TOPIC)
        layouts.append(currents_layout())
        topics.append(CURRENTS_TOPIC)
        if clock == 'sample':
            layouts.insert(0, clock_layout())
            topics.insert(0, CLOCK_TOPIC)
        self.topics = tuple(topics)
        self.state = bool(state)
        self.burst = int(burst)
        # /clock once per burst: the template with its stamp packed in (one struct call;
        # a compiled batch call per burst costs more for one small message)
        self._clock_layout = clock_layout() if clock == 'burst' else None
        self._columns = np.array([3 * k + j for k in sensors for j in range(3)])
        self._odom_cache = np.zeros(13)
        self._odom_state = b''  # bytes of the state _odom_cache was computed for
        self._parts = [RawMessageBatch(x) for x in layouts]
        self._serialiser = SampleSerialiser(self._parts)
        self._subsets: dict[tuple[bool, ...], SampleSerialiser] = {}  # of some topics only
        self._sensors = tuple(sensors)
        self._clock_per_sample = clock == 'sample'
        # load the compiled kernel now, not in the stepping thread (up to 1 s the first time)
        self._serialiser.serialise(np.zeros(1, np.int64), np.zeros((1, self._serialiser.n_values)))

    def clock_messages(self, batch: SampleBatch) -> list[bytes]:
        """``/clock`` of a batch when it goes once per burst (else none).

        Parameters
        ----------
        batch : SampleBatch
            Samples stepped, at least one.

        Returns
        -------
        list of bytes
            One Clock message per sample index that starts a burst.
        """
        layout = self._clock_layout
        if layout is None:
            return []
        burst, out = self.burst, []
        for index, t_ns in zip(batch.indices.tolist(), batch.stamps_ns.tolist(), strict=True):
            if index % burst == 0:
                message = bytearray(layout.template)
                struct.pack_into('<iI', message, layout.stamp_offset, *divmod(t_ns, 1_000_000_000))
                out.append(bytes(message))
        return out

    def sample_messages(self, batch: SampleBatch, active=None) -> list[bytes]:
        """Serialise each sample of a batch, sample after sample (``topics`` order).

        The true state's 13 odometry values are recomputed only when the state
        changed (never with the magnet fixed or absent).

        Parameters
        ----------
        batch : SampleBatch
            Samples stepped, at least one.
        active : sequence of bool, optional
            Per topic of :attr:`topics`: serialise it (default all). A topic
            nobody subscribes to need not be serialised.

        Returns
        -------
        list of bytes
            ``len(batch)`` times the messages of the active topics.
        """
        if active is None or all(active):
            values = [batch.readings[:, self._columns]]  # each published sensor's x y z
            if self.state:
                values.append(self._odometry(batch))
            values.append(batch.currents)
            return self._serialiser.serialise(batch.stamps_ns, values)
        active = tuple(bool(a) for a in active)
        serialiser = self._subsets.get(active)
        if serialiser is None:
            parts = [p for p, a in zip(self._parts, active, strict=True) if a]
            serialiser = self._subsets[active] = SampleSerialiser(parts)
        blocks = [np.zeros((len(batch), 0))] if self._clock_per_sample else []
        blocks += [batch.readings[:, 3 * k : 3 * k + 3] for k in self._sensors]
        if self.state:
            blocks.append(None)  # computed only if wanted
        blocks.append(batch.currents)
        values = []
        for block, wanted in zip(blocks, active, strict=True):
            if wanted:
                values.append(self._odometry(batch) if block is None else block)
        if not values:
            return []
        return serialiser.serialise(batch.stamps_ns, values)

    def publish(self, batch: SampleBatch, calls: Sequence, clock=None) -> int:
        """Serialise a batch and hand each message to its topic's publish call.

        ``/clock`` (once per burst) goes first, then the samples' messages
        sample after sample, in :attr:`topics` order.

        Parameters
        ----------
        batch : SampleBatch
            Samples stepped (none: nothing is published).
        calls : sequence of callable or None
            Per topic of :attr:`topics`: a call that publishes bytes, or None
            when nobody subscribes (the topic is then not even serialised).
        clock : callable, optional
            Publishes the ``/clock`` messages (``clock='burst'``).

        Returns
        -------
        int
            Sample messages published.
        """
        if not len(batch):
            return 0
        if clock is not None:
            for message in self.clock_messages(batch):
                clock(message)
        active = [call is not None for call in calls]
        wanted = [call for call in calls if call is not None]
        if not wanted:
            return 0
        messages = self.sample_messages(batch, active)
        for publish, message in zip(wanted * len(batch), messages, strict=True):
            publish(message)
        return len(messages)

    def _odometry(self, batch: SampleBatch) -> np.ndarray:
        odometry = np.empty((len(batch), 13))
        for i, state in enumerate(batch.states):
            key = state.tobytes()  # cheaper than np.array_equal at 5 kHz
            if key != self._odom_state:
                self._odom_cache = odometry_values(state)
                self._odom_state = key
            odometry[i] = self._odom_cache
        return odometry
