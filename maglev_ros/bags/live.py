"""Channels on live messages: the ROS-free core of the online identifier node.

The bag converter's channel specs (:mod:`.channels`: ``TOPIC:PATH`` and linear
combinations such as ``ux=0.5*maglev/currents:effort[0]-0.5*maglev/currents:effort[1]``)
are evaluated on messages as they arrive, instead of on a bag:

* :class:`ChannelSampler` keeps the latest value of every field the channels
  read and, each time a message of the **trigger** topic arrives, returns one
  sample ``(y, u)`` of the output and input channels (the other topics' values
  are held from their latest message: zero-order hold);
* :class:`ChannelIdentifier` feeds those samples to
  :class:`~maglev_ros.sysid.online.OnlineArx` and names the coefficient layout
  after the channels.

Pairing.  The default trigger is the topic of the first input channel (else
the first output's).  In a lockstep simulation with a controller, the
controller's ``maglev/currents/command`` for sample ``t`` is the last message
of that sample, so triggering on it pairs ``y[t]`` with ``u[t]`` exactly as the
bag converter does: the online and batch estimates are of the same samples.
:class:`StampAligner` completes samples by their stamps first, and pairs
stamped commands by theirs whatever the order of arrival
(:mod:`~maglev_ros.bags.online_identification` puts them together).  Messages
are any objects with the fields (rclpy messages or rosbags dataclasses);
nothing here imports rclpy.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass

import numpy as np

from ..sysid.online import CoefficientLayout, IdentifierStatus, OnlineArx, coefficient_layout
from .channels import Channel, FieldRef, parse_channel
from .errors import BagError
from .names import normalize_topic

__all__ = ['ChannelIdentifier', 'ChannelSampler', 'SamplerCounts', 'StampAligner']


def _getter(ref: FieldRef) -> Callable[[object], float]:
    """Compile a field path into a function reading it from a message."""
    path = ref.path

    def read(message: object) -> float:
        value = message
        for part in path:
            value = value[part] if isinstance(part, int) else getattr(value, part)
        return float(value)

    return read


@dataclass(frozen=True)
class SamplerCounts:
    """What a :class:`ChannelSampler` did with the messages it was given.

    Attributes
    ----------
    samples : int
        Samples returned.
    waiting : int
        Trigger messages dropped because some topic had not delivered yet.
    held : int
        Samples in which some non-trigger topic had no new message since the
        previous sample (its value was held).
    bad : int
        Messages without the field (or a non-numeric one), ignored.
    """

    samples: int
    waiting: int
    held: int
    bad: int


class ChannelSampler:
    """Evaluate output and input channels on live messages, one sample per trigger.

    Parameters
    ----------
    outputs, inputs : sequence of str or Channel
        Channel specs in the bag converter's syntax.
    trigger : str, optional
        Topic whose message completes a sample (default: the first input's
        topic, else the first output's; see the module docstring).

    Raises
    ------
    BagError
        A bad spec, no output, or a trigger topic that no channel reads.
    """

    def __init__(
        self,
        outputs: Sequence[str | Channel],
        inputs: Sequence[str | Channel] = (),
        trigger: str | None = None,
    ) -> None:
        if isinstance(outputs, str) or isinstance(inputs, str):
            raise BagError('outputs and inputs must be lists of channel specs, not one string')
        self.outputs = tuple(c if isinstance(c, Channel) else parse_channel(c) for c in outputs)
        self.inputs = tuple(c if isinstance(c, Channel) else parse_channel(c) for c in inputs)
        if not self.outputs:
            raise BagError('choose at least one output channel (TOPIC:FIELD)')
        refs: dict[FieldRef, int] = {}
        for chan in self.outputs + self.inputs:
            for _, ref in chan.terms:
                refs.setdefault(ref, len(refs))
        self._refs = tuple(refs)
        self.topics = tuple(dict.fromkeys(ref.topic for ref in self._refs))
        first = (self.inputs or self.outputs)[0].topics[0]
        self.trigger = first if trigger is None else normalize_topic(trigger)
        if self.trigger not in self.topics:
            raise BagError(
                f'trigger topic {self.trigger!r} is not read by any channel; '
                f'topics: {", ".join(self.topics)}'
            )
        self._by_topic = {
            t: [(refs[r], _getter(r)) for r in self._refs if r.topic == t] for t in self.topics
        }
        # channel = matrix @ field values
        self._out_matrix = self._matrix(self.outputs, refs)
        self._in_matrix = self._matrix(self.inputs, refs)
        self.reset()

    @staticmethod
    def _matrix(chans: tuple[Channel, ...], refs: dict[FieldRef, int]) -> np.ndarray:
        M = np.zeros((len(chans), len(refs)))
        for row, chan in enumerate(chans):
            for coef, ref in chan.terms:
                M[row, refs[ref]] += coef
        return M

    def reset(self) -> None:
        """Forget the latest values and the counts."""
        self._values = np.zeros(len(self._refs))
        self._seen = dict.fromkeys(self.topics, False)
        self._fresh = dict.fromkeys(self.topics, False)
        self._samples = self._waiting = self._held = self._bad = 0

    @property
    def names(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """Output and input channel names."""
        return tuple(c.name for c in self.outputs), tuple(c.name for c in self.inputs)

    @property
    def counts(self) -> SamplerCounts:
        """Samples returned, triggers dropped, samples with held values, bad messages."""
        return SamplerCounts(self._samples, self._waiting, self._held, self._bad)

    def add(self, topic: str, message: object) -> tuple[np.ndarray, np.ndarray] | None:
        """Take one message; return ``(y (ny,), u (nu,))`` when it completes a sample.

        Parameters
        ----------
        topic : str
            The message's topic (with or without the leading ``/``).
        message : object
            The message (fields as in the channel paths).

        Returns
        -------
        tuple of ndarray or None
            The sample, or None (not the trigger, a topic still silent, or a
            message without the field: counted, see :attr:`counts`).
        """
        topic = topic if topic.startswith('/') else normalize_topic(topic)
        readers = self._by_topic.get(topic)
        if readers is None:
            return None
        try:
            values = [read(message) for _, read in readers]
        except (AttributeError, IndexError, KeyError, TypeError, ValueError):
            self._bad += 1
            return None
        return self.add_values(topic, values)

    def field_paths(self, topic: str) -> tuple[tuple[str | int, ...], ...]:
        """Field paths the channels read from ``topic``, in :meth:`add_values` order.

        Parameters
        ----------
        topic : str
            Absolute topic name, one of :attr:`topics`.
        """
        return tuple(r.path for r in self._refs if r.topic == topic)

    def add_values(self, topic: str, values) -> tuple[np.ndarray, np.ndarray] | None:
        """Take one message's field values; as :meth:`add` (values read already).

        Parameters
        ----------
        topic : str
            Absolute topic name.
        values : sequence of float
            The values of :meth:`field_paths`, in order (e.g. from a
            :class:`~maglev_ros.cdr.reader.RawFieldReader` on the raw message).

        Returns
        -------
        tuple of ndarray or None
            As :meth:`add`.
        """
        readers = self._by_topic.get(topic)
        if readers is None:
            return None
        if not all(math.isfinite(v) for v in values):
            self._bad += 1
            return None
        for (k, _), v in zip(readers, values, strict=True):
            self._values[k] = v
        self._seen[topic] = self._fresh[topic] = True
        if topic != self.trigger:
            return None
        if not all(self._seen.values()):
            self._waiting += 1
            return None
        if not all(self._fresh.values()):
            self._held += 1
        self._fresh = dict.fromkeys(self.topics, False)
        self._samples += 1
        return self._out_matrix @ self._values, self._in_matrix @ self._values


class StampAligner:
    """Complete samples by header stamp before they reach a :class:`ChannelSampler`.

    The rule of the identifier node: a sample is complete when every
    **stamped** topic that the channels read (messages with a header: fields,
    currents, states) has delivered a message of the same stamp. Its messages
    are then released in topic order with the trigger topic last, so the
    sampler returns exactly one sample per stamp, whatever the order in which
    the topics' messages arrived. **Unstamped** topics (``std_msgs``
    commands, which carry no header) are released as they arrive and are
    held by the sampler (zero-order hold), as the bag converter uses their log
    time. A stamp still incomplete when a newer stamp completes is dropped
    (counted in :attr:`dropped`); at most ``depth`` incomplete stamps are kept.

    ``complete_on_next``: a completed stamp's set is not released at once but
    held until the first stamped message of a newer stamp arrives; that call
    returns the held set first, then what the new message itself releases
    (normally nothing, or nothing but its own set held in turn). Unstamped
    messages that arrive between a sample's stamped messages and the next
    sample's are then released *before* the sample's set, so the sampler
    pairs the sample with them: the command that answers sample ``t`` is
    sample ``t``'s input, as the bag converter pairs a header-less command
    logged at ``t``'s stamp (it drives the coils over ``[t, t + 1)``). This is
    the order of a real-time simulator that publishes a burst of samples and
    then the command computed from them: without it, a burst's last sample
    would be paired with the previous burst's command. The newest completed
    set waits for the next sample (one sample of latency).

    ``held_stamped``: inputs held by zero-order hold that carry the stamp of the
    sample they answer (commands as ``sensor_msgs/JointState``). A completed
    set then also waits until each such topic has delivered a message stamped
    at or after it; the held messages stamped at or before it are released
    first, so the sample's input is the newest command stamped at or before
    it: the bag converter's zero-order hold, whatever the order in which the
    topics' messages arrive. At most ``depth`` completed sets wait (then the
    oldest goes with the inputs there are).

    Parameters
    ----------
    topics : sequence of str
        Every topic the channels read (absolute names).
    stamped : collection of str
        Those whose messages carry a header stamp and make up a sample.
    trigger : str
        The sampler's trigger topic (released last in a stamp's set).
    depth : int
        Incomplete stamps kept at most.
    complete_on_next : bool
        Hold a completed set until a newer stamp's first message (see above).
    held_stamped : collection of str
        Held inputs stamped with the sample they answer (see above).
    """

    def __init__(
        self,
        topics: Sequence[str],
        stamped: Collection[str],
        trigger: str,
        depth: int = 64,
        complete_on_next: bool = False,
        held_stamped: Collection[str] = (),
    ) -> None:
        stamped, held_stamped = set(stamped), set(held_stamped)
        self.stamped = tuple(t for t in topics if t in stamped and t != trigger)
        if trigger in stamped:
            self.stamped += (trigger,)  # released last
        self.held_stamped = tuple(t for t in topics if t in held_stamped and t not in stamped)
        self.depth = int(depth)
        self.complete_on_next = bool(complete_on_next)
        self.reset()

    def reset(self) -> None:
        """Forget the pending and held messages and the count of dropped stamps."""
        self._pending: dict[int, dict[str, object]] = {}
        self._held: list[tuple[str, object]] = []
        self._held_stamp: int | None = None
        self._last: int | None = None
        self._ready: deque[tuple[int, list[tuple[str, object]]]] = deque()
        self._inputs = {t: deque() for t in self.held_stamped}  # (stamp, message) not released
        self._newest_input = dict.fromkeys(self.held_stamped)  # stamp of each one's newest
        self.dropped = 0

    def _release(self, sets: list[tuple[int, list[tuple[str, object]]]]) -> list:
        """Return the completed ``(stamp, pairs)`` sets to release now, with their inputs."""
        if not self.held_stamped:
            return [pair for _, pairs in sets for pair in pairs]
        self._ready.extend(sets)
        out: list[tuple[str, object]] = []
        while self._ready:
            stamp, pairs = self._ready[0]
            waiting = any(n is None or n < stamp for n in self._newest_input.values())
            if waiting and len(self._ready) <= self.depth:
                break
            self._ready.popleft()
            for topic, queue in self._inputs.items():
                while queue and queue[0][0] <= stamp:
                    out.append((topic, queue.popleft()[1]))
            out += pairs
        return out

    def add(self, topic: str, stamp_ns: int | None, message: object) -> list[tuple[str, object]]:
        """Take one message; return the ``(topic, message)`` pairs to give the sampler now.

        Parameters
        ----------
        topic : str
            Absolute topic name.
        stamp_ns : int or None
            Header stamp, ns (None for an unstamped topic).
        message : object
            The message.

        Returns
        -------
        list of (str, object)
            Empty while the message's stamp is incomplete; a stamp's full set
            (trigger last) when this message completes it; the message itself
            for an unstamped topic. With ``complete_on_next``, a completed set
            comes with the first message of a newer stamp instead, before
            what that message releases.
        """
        if topic in self.held_stamped and stamp_ns is not None:
            self._inputs[topic].append((stamp_ns, message))
            newest = self._newest_input[topic]
            self._newest_input[topic] = stamp_ns if newest is None else max(newest, stamp_ns)
            return self._release([])
        if topic not in self.stamped or stamp_ns is None:
            return [(topic, message)]
        if self._last is not None and stamp_ns <= self._last:
            self.dropped += 1  # late: its stamp was completed or dropped already
            return []
        sets = [(self._held_stamp, self._held)] if self._held else []  # it goes first
        self._held = []
        group = self._pending.setdefault(stamp_ns, {})
        group[topic] = message
        if len(group) < len(self.stamped):
            while len(self._pending) > self.depth:  # the oldest first (stamps come in order)
                del self._pending[next(iter(self._pending))]
                self.dropped += 1
            return self._release(sets)
        for old in [s for s in self._pending if s <= stamp_ns]:
            if old != stamp_ns:
                self.dropped += 1
            del self._pending[old]
        self._last = stamp_ns
        complete = [(t, group[t]) for t in self.stamped]
        if self.complete_on_next:
            self._held, self._held_stamp = complete, stamp_ns
            return self._release(sets)
        return self._release([*sets, (stamp_ns, complete)])


class ChannelIdentifier:
    """Online recursive ARX on channels of live messages.

    Parameters
    ----------
    outputs, inputs : sequence of str or Channel
        Channel specs (the bag converter's syntax), SISO or MISO/MIMO.
    na : int or array_like (ny, ny)
        Orders of ``A``.
    nb, nk : int or array_like (ny, nu)
        Numbers of ``B`` coefficients and input delays, samples.
    trigger : str, optional
        Topic that completes a sample (see :class:`ChannelSampler`).
    **options
        :class:`~maglev_ros.sysid.online.OnlineArx` settings: ``forgetting``
        (default 1), ``initial_covariance`` (1e4), ``window`` (None),
        ``fit_window`` (1000), ``wait_for_history`` (True).
    """

    def __init__(
        self,
        outputs: Sequence[str | Channel],
        inputs: Sequence[str | Channel],
        na: object,
        nb: object,
        nk: object = 1,
        trigger: str | None = None,
        **options: object,
    ) -> None:
        self.sampler = ChannelSampler(outputs, inputs, trigger)
        ny, nu = len(self.sampler.outputs), len(self.sampler.inputs)
        if nu == 0:
            raise BagError('choose at least one input channel for ARX (TOPIC:FIELD)')
        self.arx = OnlineArx(na, nb, nk, ny, nu, **options)  # type: ignore[arg-type]

    @property
    def topics(self) -> tuple[str, ...]:
        """Topics to subscribe to."""
        return self.sampler.topics

    def add(self, topic: str, message: object) -> np.ndarray | None:
        """Take one message; on a completed sample update, return the prediction error (ny,).

        Parameters
        ----------
        topic : str
            The message's topic (with or without the leading ``/``).
        message : object
            The message (fields as in the channel paths).

        Returns
        -------
        ndarray or None
            The a-priori prediction error, shape (ny,), output units; None when
            the message completes no sample.

        Raises
        ------
        ValueError
            If the sample is not finite (the estimate is left unchanged).
        """
        sample = self.sampler.add(topic, message)
        if sample is None:
            return None
        return self.arx.update(*sample)

    def reset(self) -> None:
        """Restart the estimate (and the sampler's held values)."""
        self.arx.reset()
        self.sampler.reset()

    def status(self) -> IdentifierStatus:
        """Diagnostics snapshot (see :meth:`OnlineArx.status`)."""
        return self.arx.status()

    def layout(self) -> CoefficientLayout:
        """Return the coefficients with dimension labels named after the channels."""
        outs, ins = self.sampler.names
        return coefficient_layout(self.arx.orders, self.arx.theta, outs, ins)

    def model(self, Ts: float):  # noqa: ANN201 - PolyModel
        """Return the current estimate as an ARX PolyModel with sample time ``Ts`` (s).

        Parameters
        ----------
        Ts : float
            Sample time, s.
        """
        outs, ins = self.sampler.names
        return self.arx.model(Ts, outs, ins)
