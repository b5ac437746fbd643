"""The recording window: which messages a recording keeps, and at which log time.

A recording may keep only the messages logged between ``start`` and ``end``
(ns of log time; ``end`` None: no end), e.g. exactly the samples of a lab's
experiment from subscriptions matched long before, out of a simulation that
runs on. Two kinds of topic:

* **sample** topics (fields, currents, states, ``/clock``): a message inside
  the window is kept at its log time, one outside is dropped;
* **held** topics (commands, excitation, header-less messages): an input the
  plant holds until the next message (zero-order hold), as the bag converter
  reads it (:mod:`~maglev_ros.bags.alignment`). Two rules keep such an input
  in force over the whole window:

  - **start**: the newest held message logged before ``start`` is the one in
    force at the window's first sample; it is kept at ``start`` (before the
    topic's first message inside the window, unless that one is logged at
    ``start`` itself and supersedes it);
  - **end**: the converter holds an input for one of its own periods after its
    last message, so a window ending long after its last command would be
    trimmed. When the window has an end, the held message in force at the
    newest sample kept is logged once more at that sample's time: once both
    the held topic and a sample topic have delivered a message after ``end``,
    or when the recording closes.

A middleware delivers the messages of one topic in order, but not those of
different topics: a topic's first message after a bound says that all its
messages before it are in, so the rules wait for those and depend on no order
across topics. The window may be moved at any time
(:meth:`RecordingWindow.set`): a lab starts with an empty one and sets it once
the settling is over; the newest held message seen stays the candidate for the
new window's start.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import NamedTuple

from .errors import BagError

__all__ = ['Kept', 'RecordingWindow']


class Kept(NamedTuple):
    """One message to write.

    Attributes
    ----------
    topic : hashable
        The topic (as the caller names it).
    log_time : int
        Log time to write it at, ns.
    message : object
        The message (e.g. its CDR bytes), as offered.
    """

    topic: Hashable
    log_time: int
    message: object


class RecordingWindow:
    """Keep the messages of a log-time window (see the module docstring).

    Parameters
    ----------
    start_ns : int
        First log time kept, ns (0: from the first message).
    end_ns : int or None
        Last log time kept, ns (None: no end).

    Raises
    ------
    BagError
        If ``end_ns`` is before ``start_ns`` or ``start_ns`` is negative.
    """

    def __init__(self, start_ns: int = 0, end_ns: int | None = None) -> None:
        # per held topic: the newest message offered, (log time, message, kept)
        self._in_force: dict[Hashable, tuple[int, object, bool]] = {}
        self._after: dict[Hashable, tuple[int, object, bool]] = {}  # newest after the end
        self.set(start_ns, end_ns)

    @property
    def start_ns(self) -> int:
        """First log time kept, ns."""
        return self._start

    @property
    def end_ns(self) -> int | None:
        """Last log time kept, ns (None: no end)."""
        return self._end

    @property
    def newest_sample_ns(self) -> int | None:
        """Log time of the newest sample-topic message kept in this window, ns (None: none)."""
        return self._newest

    def set(self, start_ns: int, end_ns: int | None = None) -> None:
        """Move the window (its rules start over; the held messages seen stay candidates).

        Parameters
        ----------
        start_ns : int
            First log time kept, ns.
        end_ns : int or None
            Last log time kept, ns (None: no end).

        Raises
        ------
        BagError
            If ``end_ns`` is before ``start_ns`` or ``start_ns`` is negative.
        """
        start_ns = int(start_ns)
        if start_ns < 0:
            raise BagError(f'the window must start at a log time >= 0 ns, got {start_ns}')
        if end_ns is not None and int(end_ns) < start_ns:
            raise BagError(
                f'the window must end at or after its start {start_ns} ns, got {int(end_ns)} ns'
            )
        self._in_force.update(self._after)  # the newest seen of each topic
        self._after = {}
        self._start = start_ns
        self._end = None if end_ns is None else int(end_ns)
        self._newest: int | None = None
        self._started: set[Hashable] = set()  # held topics with a message inside
        self._finished: set[Hashable] = set()  # held topics whose end rule ran
        self._ended: set[Hashable] = set()  # held topics with a message after the end
        self._samples_ended = False  # a sample after the end came

    def offer(
        self, topic: Hashable, log_time: int, message: object, held: bool = False
    ) -> list[Kept]:
        """Take one message; return what to write now, in order.

        Parameters
        ----------
        topic : hashable
            Its topic.
        log_time : int
            Its log time, ns.
        message : object
            The message (returned as is).
        held : bool
            Whether the topic is held (commands; see the module docstring).

        Returns
        -------
        list of Kept
            Nothing (outside the window), the message itself, or for a held
            topic the message in force before it (at ``start``) or at the
            window's end.
        """
        if not held:
            if self._end is not None and log_time > self._end:
                self._samples_ended = True  # this topic's samples of the window are all in
                return [k for topic in list(self._ended) for k in self._finish(topic)]
            if log_time < self._start:
                return []
            if self._newest is None or log_time > self._newest:
                self._newest = log_time
            return [Kept(topic, log_time, message)]
        if log_time < self._start:
            self._in_force[topic] = (log_time, message, False)
            return []
        if self._end is not None and log_time > self._end:
            self._ended.add(topic)  # this topic's messages of the window are all in
            self._after[topic] = (log_time, message, False)  # a later window's candidate
            return self._finish(topic) if self._samples_ended else []
        kept = []
        if topic not in self._started:
            self._started.add(topic)
            before = self._in_force.get(topic)
            if before is not None and not before[2] and before[0] < self._start < log_time:
                kept.append(Kept(topic, self._start, before[1]))
        kept.append(Kept(topic, log_time, message))
        self._in_force[topic] = (log_time, message, True)
        return kept

    def _finish(self, topic: Hashable) -> list[Kept]:
        """Apply the end rule to one held topic (once per window)."""
        if topic in self._finished or self._newest is None:
            return []
        self._finished.add(topic)
        in_force = self._in_force.get(topic)
        if in_force is None:
            return []
        log_time, message, kept = in_force
        out = []
        if topic not in self._started:  # nothing inside: the one from before holds throughout
            if kept or log_time >= self._start:
                return []
            self._started.add(topic)
            out.append(Kept(topic, self._start, message))
            log_time = self._start
        if log_time < self._newest:
            out.append(Kept(topic, self._newest, message))
        return out

    def close(self) -> list[Kept]:
        """Return what the rules still owe when the recording ends (call once, last).

        The held messages in force at the window's start that no message
        inside followed (a window of a few samples), kept at ``start``; with an
        end, those in force at the newest sample, kept there.

        Returns
        -------
        list of Kept
            In topic order.
        """
        if self._newest is None:
            return []
        out: list[Kept] = []
        for topic in list(self._in_force):
            if self._end is not None:
                out += self._finish(topic)
                continue
            log_time, message, kept = self._in_force[topic]
            if topic not in self._started and not kept and log_time < self._start:
                self._started.add(topic)
                out.append(Kept(topic, self._start, message))
        return out
