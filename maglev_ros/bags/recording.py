"""A recording: serialised messages as they arrive -> a bag, at their log times, in a window.

The ROS-free core of the recorder node (and of any loop observer that writes
bags): it takes each message's CDR bytes, gives it a log time (:class:`LogClock`),
keeps it if the :class:`~maglev_ros.bags.recording_window.RecordingWindow`
says so, and writes it with a :class:`~maglev_ros.bags.writer.BagWriter`,
counting the messages of each topic.

Log times (``log_clock``):

* ``ros``: the caller's clock (the node's: wall time, or ``/clock`` with
  ``use_sim_time``);
* ``topic``: the newest ``/clock`` message recorded (``/clock`` must be among
  the topics): every message of a lockstep run is logged at the simulated
  time of its sample;
* ``stamp``: a message with a header (and ``/clock``) at its own stamp; so the
  commands (``sensor_msgs/JointState``, stamped with the sample they answer)
  align with their sample exactly. A header-less message (a command of an
  older publisher, ``std_msgs/Float64MultiArray``) is logged at the newest
  stamp recorded before it.

Held topics (:data:`HELD_TOPICS`: the commands and the excitation, and every
header-less topic) follow the window's rules for inputs.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata as importlib_metadata

from ..topics import CLOCK_TOPIC
from .channels import COMMAND_TOPICS
from .errors import BagError
from .names import normalize_topic
from .recording_window import Kept, RecordingWindow
from .writer import BagWriter, TopicHandle

__all__ = [
    'HELD_TOPICS',
    'LOG_CLOCKS',
    'LogClock',
    'Recording',
    'RecordingConfig',
    'header_stamp_ns',
    'package_version',
]

#: Log clocks a recording understands (see the module docstring).
LOG_CLOCKS = ('ros', 'topic', 'stamp')
#: Topics of inputs that the plant holds until the next message (absolute names).
HELD_TOPICS = COMMAND_TOPICS
# the header's stamp (a Clock's time) right after the 4-byte CDR encapsulation header
_STAMP = struct.Struct('<iI')


def header_stamp_ns(data: bytes) -> int:
    """Return the stamp of a serialised message whose first field is a header (or a Clock), ns.

    Parameters
    ----------
    data : bytes
        The message's CDR bytes (little- or big-endian encapsulation).

    Returns
    -------
    int
        ``sec * 1e9 + nanosec``.
    """
    if len(data) < 12:
        raise BagError(f'a stamped message needs at least 12 bytes, got {len(data)}')
    layout = _STAMP if data[1] & 1 else struct.Struct('>iI')
    sec, nanosec = layout.unpack_from(data, 4)
    return sec * 1_000_000_000 + nanosec


@dataclass(frozen=True)
class RecordingConfig:
    """What to record, how and when (the recorder node's validated parameters).

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
    """

    path: str
    storage: str
    topics: tuple[str, ...]
    depth: int
    log_clock: str
    metadata_node: str
    record_from: float = 0.0
    record_until: float = 0.0

    @property
    def window_ns(self) -> tuple[int, int | None]:
        """``(record_from, record_until)`` in ns of log time (None: no end)."""
        return round(self.record_from * 1e9), round(self.record_until * 1e9) or None

    def metadata(self) -> dict[str, object]:
        """Return the bag's metadata of this recording (version, settings, start time)."""
        return {
            'maglev_ros.version': package_version(),
            'recorder.storage': self.storage,
            'recorder.topics': ' '.join(self.topics),
            'recorder.log_clock': self.log_clock,
            'recorder.record_from': self.record_from,
            'recorder.record_until': self.record_until,
            'recorder.started': time.strftime('%Y-%m-%dT%H:%M:%S%z'),
        }


def package_version() -> str:
    """Return the installed maglev_ros version ('unknown' if not installed)."""
    try:
        return importlib_metadata.version('maglev_ros')
    except importlib_metadata.PackageNotFoundError:
        return 'unknown'


class LogClock:
    """Log times of serialised messages (see the module docstring).

    Parameters
    ----------
    mode : str
        ``ros``, ``topic`` or ``stamp``.
    now : callable
        ``now() -> int``: the caller's clock, ns (used by ``ros``).
    """

    def __init__(self, mode: str, now: Callable[[], int]) -> None:
        if mode not in LOG_CLOCKS:
            raise BagError(f'log clock must be one of {", ".join(LOG_CLOCKS)}, got {mode!r}')
        self.mode = mode
        self._now = now
        self._clock_ns = 0  # topic: newest /clock; stamp: newest stamp

    def log_time(self, data: bytes, stamped: bool, is_clock: bool = False) -> int:
        """Return the log time of one message, ns.

        Parameters
        ----------
        data : bytes
            Its CDR bytes.
        stamped : bool
            Whether it starts with a header (``/clock``: True).
        is_clock : bool
            Whether it is a ``/clock`` message.

        Returns
        -------
        int
        """
        if self.mode == 'ros':
            return int(self._now())
        if self.mode == 'topic':
            if is_clock:
                self._clock_ns = header_stamp_ns(data)
            return self._clock_ns
        if not stamped:
            return self._clock_ns
        stamp = header_stamp_ns(data)
        self._clock_ns = max(self._clock_ns, stamp)
        return stamp


class Recording:
    """Messages -> bag, at their log times, inside a window (see the module docstring).

    Parameters
    ----------
    writer : BagWriter
        An open bag writer (closed by :meth:`close`).
    log_clock : str
        ``ros``, ``topic`` or ``stamp``.
    now : callable
        ``now() -> int``, ns: the clock of ``log_clock: ros``.
    start_ns, end_ns : int, int or None
        The window, ns of log time (see :class:`RecordingWindow`).
    """

    def __init__(
        self,
        writer: BagWriter,
        log_clock: str,
        now: Callable[[], int],
        start_ns: int = 0,
        end_ns: int | None = None,
    ) -> None:
        self.writer = writer
        self.clock = LogClock(log_clock, now)
        self.window = RecordingWindow(start_ns, end_ns)
        self.counts: dict[str, int] = {}
        # per topic: handle, stamped, held, is_clock
        self._topics: dict[str, tuple[TopicHandle, bool, bool, bool]] = {}
        self._closed = False

    def add_topic(self, topic: str, msgtype: str, stamped: bool) -> None:
        """Register a topic in the bag.

        Parameters
        ----------
        topic : str
            Topic name.
        msgtype : str
            Its message type, ``pkg/msg/Type``.
        stamped : bool
            Whether its messages start with a ``std_msgs/Header``.

        Raises
        ------
        BagError
            The bag refuses the topic (unknown type, added twice, closed).
        """
        name = normalize_topic(topic)
        handle = self.writer.add_topic(name, msgtype)
        is_clock = name == CLOCK_TOPIC
        held = name in HELD_TOPICS or not (stamped or is_clock)
        self._topics[name] = (handle, stamped or is_clock, held, is_clock)
        self.counts.setdefault(name, 0)

    def set_window(self, start_ns: int, end_ns: int | None = None) -> None:
        """Move the window (see :meth:`RecordingWindow.set`).

        Parameters
        ----------
        start_ns : int
            First log time kept, ns.
        end_ns : int or None
            Last log time kept, ns (None: no end).
        """
        self.window.set(start_ns, end_ns)

    def write(self, topic: str, data: bytes) -> int:
        """Log one serialised message of a registered topic.

        Parameters
        ----------
        topic : str
            Its topic (as registered, absolute).
        data : bytes
            Its CDR bytes.

        Returns
        -------
        int
            Messages written (0: outside the window or the bag closed).
        """
        if self._closed:
            return 0
        _, stamped, held, is_clock = self._topics[topic]
        log_time = self.clock.log_time(data, stamped, is_clock)
        return self._write(self.window.offer(topic, log_time, data, held))

    def _write(self, kept: list[Kept]) -> int:
        write, topics, counts = self.writer.write, self._topics, self.counts
        for topic, log_time, message in kept:
            write(topics[topic][0], log_time, message)
            counts[topic] += 1
        return len(kept)

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._closed

    @property
    def total(self) -> int:
        """Messages written."""
        return sum(self.counts.values())

    def close(self) -> None:
        """Write what the window's rules still owe and finalise the bag (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._write(self.window.close())
        finally:
            self.writer.close()
