"""Write rosbag2 bags (MCAP or sqlite3) from CDR-serialised messages, without ROS.

:class:`BagWriter` wraps :class:`rosbags.rosbag2.Writer` so that a pip-only
machine can record: it takes the bytes a ``raw=True`` subscription (or
``rclpy.serialization.serialize_message``) delivers, stores them unchanged, and
always finalises the bag (storage index and ``metadata.yaml``) on
:meth:`BagWriter.close`, also when the ``with`` block ends with an exception.

The bag is written in rosbag2 format version 8 (the one ROS 2 Jazzy writes), so
``ros2 bag info`` / ``ros2 bag play`` read it.  Run metadata (a flat dict of
strings, numbers and booleans) goes into the bag's ``custom_data``, one key per
item, each value a YAML scalar so that :func:`maglev_ros.bags.reader.BagReader`
gives back the original types.
"""

from __future__ import annotations

import sqlite3
import struct
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import numpy as np
import yaml
from rosbags.interfaces import Connection, Qos
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys.store import Typestore

from .errors import BagError
from .names import normalize_msgtype, normalize_topic
from .typestore import jazzy_typestore

__all__ = ['FLUSH_PERIOD_S', 'STORAGES', 'BagWriter', 'TopicHandle', 'encode_metadata']

#: Storage plugins by name (``ros2 bag record --storage``).
STORAGES: dict[str, StoragePlugin] = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
#: rosbag2 metadata version written (ROS 2 Jazzy writes 8).
BAG_VERSION = 8
FLUSH_PERIOD_S = 1.0  # s between flushes of written messages into the file
_SCALARS = (str, int, float, bool)
# an MCAP message record: opcode, record length; channel id, sequence, log and publish time
_MCAP_MESSAGE = struct.Struct('<BQHIQQ')
_MCAP_MESSAGE_FIELDS = 2 + 4 + 8 + 8  # the record's bytes before the data


def encode_metadata(metadata: Mapping[str, object] | None) -> dict[str, str]:
    """Check run metadata and encode each value as a YAML scalar string.

    Parameters
    ----------
    metadata : mapping of str to str, int, float, bool or None, optional
        Flat run metadata (parameter set, model options, seed, package version ...).

    Returns
    -------
    dict of str to str
        The ``custom_data`` entries.
    """
    encoded: dict[str, str] = {}
    for key, value in (metadata or {}).items():
        if not isinstance(key, str) or not key:
            raise BagError(f'metadata keys must be non-empty strings, got {key!r}')
        if isinstance(value, np.generic):  # numpy scalars (a seed from a Generator ...)
            value = value.item()
        if value is not None and not isinstance(value, _SCALARS):
            raise BagError(
                f'metadata {key!r} must be a string, number or boolean (flatten '
                f'nested options into keys such as "model.field"), '
                f'got {type(value).__name__}'
            )
        text = yaml.safe_dump(value, default_flow_style=True, width=10**6).strip()
        encoded[key] = text.removesuffix('\n...').removesuffix('...').strip()
    return encoded


@dataclass(frozen=True, eq=False)
class TopicHandle:
    """A topic added to a :class:`BagWriter`; pass it to :meth:`BagWriter.write`.

    Parameters
    ----------
    name : str
        Absolute topic name.
    msgtype : str
        Message type ``pkg/msg/Type``.
    connection : rosbags.interfaces.Connection
        The rosbags connection the messages are written to.
    """

    name: str
    msgtype: str
    connection: Connection


class BagWriter:
    """A rosbag2 bag being written: open, add topics, write CDR bytes, close.

    Parameters
    ----------
    path : str or Path
        Bag directory to create; it must not exist.
    storage : {'mcap', 'sqlite3'}
        Storage plugin (default ``'mcap'``, as ``ros2 bag record``).
    metadata : mapping, optional
        Flat run metadata stored in the bag's ``custom_data``.
    typestore : rosbags Typestore, optional
        Message definitions (default: ROS 2 Jazzy's standard messages).

    Notes
    -----
    Thread-safe: :meth:`add_topic`, :meth:`write` and :meth:`close` take one
    lock, so subscription callbacks on several executor threads may write while
    another thread closes (also for sqlite3, whose connection is not tied to the
    opening thread).  :meth:`write` stores the bytes before it returns (MCAP:
    into the current chunk; sqlite3: into the open transaction); every
    ``FLUSH_PERIOD_S`` (1 s) a write also puts them into the file
    (:meth:`flush`).  :meth:`close` is idempotent; call it from the ``finally``
    of the recorder's ``main`` (or a shutdown callback).  Writing after
    :meth:`close` raises :class:`BagError`.  A bag is readable once
    :meth:`close` has written ``metadata.yaml``; a process killed with SIGKILL
    leaves an unfinished bag, which :func:`maglev_ros.bags.reindex` rebuilds
    with every message up to the last flush (at most about 1 s is lost).
    """

    def __init__(
        self,
        path: str | Path,
        storage: str = 'mcap',
        metadata: Mapping[str, object] | None = None,
        typestore: Typestore | None = None,
    ) -> None:
        if storage not in STORAGES:
            raise BagError(f'unknown bag storage {storage!r} (use one of {sorted(STORAGES)})')
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'bag directory {str(self.path)!r} exists already; choose a new name')
        self.storage = storage
        self.metadata = dict(metadata or {})
        self._custom = encode_metadata(self.metadata)
        self._typestore = typestore or jazzy_typestore()
        self._writer = Writer(self.path, version=BAG_VERSION, storage_plugin=STORAGES[storage])
        self._topics: dict[str, TopicHandle] = {}
        self._lock = threading.RLock()
        self._state = 'new'
        self.message_count = 0
        self._flush_due = time.monotonic() + FLUSH_PERIOD_S

    # ------------------------------------------------------------ lifecycle
    @property
    def is_open(self) -> bool:
        """Whether the bag accepts topics and messages."""
        return self._state == 'open'

    def open(self) -> BagWriter:
        """Create the bag directory and its storage file.

        Returns
        -------
        BagWriter
            ``self``.
        """
        with self._lock:
            if self._state != 'new':
                raise BagError(f'bag {str(self.path)!r} was opened already')
            try:
                self._writer.open()
            except (WriterError, OSError) as exc:
                raise BagError(f'cannot create bag {str(self.path)!r}: {exc}') from None
            self._unbind_sqlite_thread()
            for key, value in self._custom.items():
                self._writer.set_custom_data(key, value)
            self._state = 'open'
        return self

    def _unbind_sqlite_thread(self) -> None:
        """Let any thread write to a sqlite3 bag (writes are serialised by the lock).

        rosbags opens the database with Python's default ``check_same_thread``,
        which ties it to the opening thread; a recorder's callbacks run on executor
        threads.  The schema is committed already, so reconnecting loses nothing.
        """
        storage = self._writer.storage
        conn = getattr(storage, 'conn', None)
        if not isinstance(conn, sqlite3.Connection) or not hasattr(storage, 'cursor'):
            return
        conn.commit()
        conn.close()
        storage.conn = sqlite3.connect(f'file:{storage.path}', uri=True, check_same_thread=False)
        storage.cursor = storage.conn.cursor()

    def close(self) -> None:
        """Finalise the bag: write the storage index and ``metadata.yaml`` (idempotent)."""
        with self._lock:
            if self._state != 'open':
                self._state = 'closed'
                return
            self._state = 'closed'
            try:
                self._writer.close()
            except BaseException:
                self._writer.abort()
                raise

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # finalise also on errors and KeyboardInterrupt: what was written stays readable
        self.close()

    def set_metadata(self, metadata: Mapping[str, object]) -> None:
        """Add or replace run metadata items before :meth:`close` (e.g. how the run ended).

        Parameters
        ----------
        metadata : mapping
            Flat items, as the ``metadata`` argument.
        """
        encoded = encode_metadata(metadata)
        with self._lock:
            if self._state == 'closed':
                raise BagError(f'bag {str(self.path)!r} is closed')
            self.metadata.update(metadata)
            self._custom.update(encoded)
            if self._state == 'open':
                for key, value in encoded.items():
                    self._writer.set_custom_data(key, value)

    # -------------------------------------------------------------- writing
    def add_topic(
        self,
        name: str,
        msgtype: str,
        serialization_format: str = 'cdr',
        offered_qos: Sequence[Qos] | None = None,
    ) -> TopicHandle:
        """Register a topic; returns the handle to write its messages with.

        Parameters
        ----------
        name : str
            Topic name, with or without the leading ``/``.
        msgtype : str
            Message type, ``pkg/msg/Type`` (or ``pkg/Type``), known to the type store.
        serialization_format : str
            ``'cdr'`` (what rclpy and rosbags produce).
        offered_qos : sequence of rosbags Qos, optional
            The publishers' QoS profiles, stored for ``ros2 bag play``.

        Returns
        -------
        TopicHandle
            The topic's handle.
        """
        topic, msgtype = normalize_topic(name), normalize_msgtype(msgtype)
        with self._lock:
            self._check_open()
            if topic in self._topics:
                raise BagError(f'topic {topic!r} was added to bag {str(self.path)!r} already')
            if msgtype not in self._typestore.fielddefs:
                raise BagError(
                    f'unknown message type {msgtype!r} for topic {topic!r} (not in '
                    f'the type store; pass typestore= with its definition)'
                )
            connection = self._writer.add_connection(
                topic,
                msgtype,
                typestore=self._typestore,
                serialization_format=serialization_format,
                offered_qos_profiles=list(offered_qos or ()),
            )
            handle = TopicHandle(topic, msgtype, connection)
            self._topics[topic] = handle
            return handle

    def write_many(
        self, topic: TopicHandle | str, timestamps_ns: Sequence[int], messages: Sequence[bytes]
    ) -> None:
        """Write several serialised messages of one topic, in order (as :meth:`write` each).

        MCAP: the message records are appended to the open chunk directly,
        with rosbags' own bookkeeping (the file is byte for byte what
        :meth:`write` makes: ``test/bags/test_writer_reader.py``), about 3x
        faster per message; a 5 kHz recording composed with a real-time loop
        runs in the loop's thread. sqlite3: one :meth:`write` each.

        Parameters
        ----------
        topic : TopicHandle or str
            As for :meth:`write`.
        timestamps_ns : sequence of int
            Log time of each message, ns (>= 0).
        messages : sequence of bytes
            The CDR-serialised messages.
        """
        if len(timestamps_ns) != len(messages):
            raise BagError(
                f'write_many needs one timestamp per message, got {len(timestamps_ns)} and '
                f'{len(messages)}'
            )
        if not messages:
            return
        storage = self._writer.storage
        if not hasattr(storage, 'close_chunk') or self._writer.compression_mode.name != 'NONE':
            for stamp, data in zip(timestamps_ns, messages, strict=True):
                self.write(topic, stamp, data)
            return
        with self._lock:
            self._check_open()
            handle = self._handle_of(topic)
            stamps = [int(t) for t in timestamps_ns]
            lo, hi = min(stamps), max(stamps)
            if lo < 0:
                raise BagError(f'timestamp must be >= 0 ns, got {lo!r}')
            cid = handle.connection.id
            pack = _MCAP_MESSAGE.pack
            chunk = storage.chunk
            bio, index = chunk.bio, chunk.msgs[cid]
            for stamp, data in zip(stamps, messages, strict=True):
                chunk.message_start_time = min(stamp, chunk.message_start_time)
                chunk.message_end_time = max(stamp, chunk.message_end_time)
                index.append((stamp, bio.tell()))
                bio.write(pack(0x05, _MCAP_MESSAGE_FIELDS + len(data), cid, 0, stamp, stamp))
                bio.write(data)
                if bio.tell() > 2**20:  # rosbags' chunk size: a new chunk, as write makes
                    storage.close_chunk()
                    chunk = storage.chunk
                    bio, index = chunk.bio, chunk.msgs[cid]
            n = len(stamps)
            storage.message_start_time = min(lo, storage.message_start_time)
            storage.message_end_time = max(hi, storage.message_end_time)
            storage.channel_stats[cid] += n
            writer = self._writer
            writer.counts[cid] += n
            writer.min_timestamp = min(lo, writer.min_timestamp)
            writer.max_timestamp = max(hi, writer.max_timestamp)
            self.message_count += n
            if time.monotonic() >= self._flush_due:
                self.flush()

    def _handle_of(self, topic: TopicHandle | str) -> TopicHandle:
        handle = (
            topic if isinstance(topic, TopicHandle) else self._topics.get(normalize_topic(topic))
        )
        if handle is None or self._topics.get(handle.name) is not handle:
            raise BagError(
                f'topic {topic if isinstance(topic, str) else topic.name!r} '
                f'was not added to bag {str(self.path)!r} '
                f'(topics: {sorted(self._topics)})'
            )
        return handle

    def write(self, topic: TopicHandle | str, timestamp_ns: int, data: bytes) -> None:
        """Write one serialised message.

        Parameters
        ----------
        topic : TopicHandle or str
            The handle from :meth:`add_topic`, or the topic name.
        timestamp_ns : int
            Log (receive) time in nanoseconds since the epoch (or of the ROS clock).
        data : bytes
            The CDR-serialised message, with its 4-byte encapsulation header.
        """
        with self._lock:
            self._check_open()
            handle = self._handle_of(topic)
            stamp = int(timestamp_ns)
            if stamp < 0:
                raise BagError(f'timestamp must be >= 0 ns, got {timestamp_ns!r}')
            self._write_whole(handle.connection, stamp, data)
            self.message_count += 1
            if time.monotonic() >= self._flush_due:
                self.flush()

    def _write_whole(self, connection, stamp: int, data: bytes) -> None:
        """Write one message, or nothing of it when an exception interrupts the write.

        A signal handler that raises (``sys.exit`` on SIGTERM, ``KeyboardInterrupt``)
        can interrupt the storage's write between two of a record's fields; the
        chunk would then hold a partial record that the close writes out, and the
        bag would not read. MCAP: the chunk's buffer and message index are put back
        as they were before the message, then the exception goes on.
        """
        storage = self._writer.storage
        chunk = getattr(storage, 'chunk', None)  # rosbags' MCAP writer
        if chunk is None:
            self._writer.write(connection, stamp, data)
            return
        start = chunk.bio.tell()
        index = chunk.msgs[connection.id]
        entries = len(index)
        try:
            self._writer.write(connection, stamp, data)
        except BaseException:
            if chunk is storage.chunk and chunk.bio.tell() != start:  # not closed meanwhile
                chunk.bio.seek(start)
                chunk.bio.truncate()
                del index[entries:]
            raise

    def flush(self) -> None:
        """Put every message written so far into the file (done every FLUSH_PERIOD_S).

        MCAP: the open chunk is closed and the file buffer flushed; sqlite3: the
        transaction is committed. A process killed after this (SIGKILL, power
        loss) leaves these messages in the file: :func:`maglev_ros.bags.reindex`
        rebuilds such a bag.
        """
        with self._lock:
            self._flush_due = time.monotonic() + FLUSH_PERIOD_S
            if self._state != 'open':
                return
            storage = self._writer.storage
            if hasattr(storage, 'close_chunk'):  # rosbags' MCAP writer
                if storage.chunk.bio.tell():
                    storage.close_chunk()
                storage.bio.flush()
            elif isinstance(getattr(storage, 'conn', None), sqlite3.Connection):
                storage.conn.commit()

    def _check_open(self) -> None:
        if self._state == 'new':
            raise BagError(f'bag {str(self.path)!r} is not open (use it in a with block)')
        if self._state == 'closed':
            raise BagError(f'bag {str(self.path)!r} is closed')
