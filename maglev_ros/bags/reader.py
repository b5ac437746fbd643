"""Read rosbag2 bags (MCAP or sqlite3; ours or ``ros2 bag record``'s) without ROS.

:class:`BagReader` opens a bag directory with :class:`rosbags.rosbag2.Reader`,
lists its topics, gives the run metadata and iterates over raw messages of
chosen topics.  Every failure is a :class:`~maglev_ros.bags.errors.BagError`
with one message: missing or empty directory, no ``metadata.yaml``, empty
bag, truncated or corrupt storage file, unknown topic (the message lists the
topics the bag has).

Run metadata is read from the bag's ``custom_data`` (written by
:class:`~maglev_ros.bags.writer.BagWriter`) and from a ``/maglev/metadata``
topic (``std_msgs/msg/String`` holding a YAML mapping, the way to carry the
metadata through ``ros2 bag record``); the topic's entries win.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import yaml
from rosbags.rosbag2 import Reader, ReaderError
from rosbags.typesys.store import Typestore

from ..topics import METADATA_TOPIC  # the run metadata (std_msgs/String, YAML)
from .errors import BagError
from .names import normalize_topic
from .typestore import bag_typestore, cdr_deserializer

__all__ = [
    'METADATA_TOPIC',
    'BagReader',
    'TopicInfo',
    'decode_metadata',
    'is_bag_directory',
    'is_bag_path',
]

_STORAGE_SUFFIXES = {'.mcap': 'mcap', '.db3': 'sqlite3'}
# rosbags' messages about metadata.yaml (rosbag2/reader.py)
_METADATA_ERRORS = (
    'Could not load YAML',
    'Could not read metadata',
    'A metadata key',
    'Invalid bag metadata',
    'Rosbag2 version',
    'Storage plugin',
    'Compression format',
    'Serialization format',
)


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag.

    Parameters
    ----------
    name : str
        Absolute topic name.
    msgtype : str
        Message type ``pkg/msg/Type``.
    count : int
        Number of messages according to the bag's index.
    """

    name: str
    msgtype: str
    count: int


def is_bag_path(path: str | Path) -> bool:
    """Whether a path names a bag rather than a data file (for tools taking either).

    Parameters
    ----------
    path : str or Path
        A directory (a bag, finished or not) or a ``.mcap`` / ``.db3`` file.

    Returns
    -------
    bool
        True for a directory or a bag storage file.
    """
    path = Path(path)
    return path.is_dir() or path.suffix in _STORAGE_SUFFIXES


# what a rosbag2 directory holds, finished or not (sqlite3 keeps its journal beside)
_BAG_FILE_SUFFIXES = ('.mcap', '.db3', '.db3-wal', '.db3-shm', '.db3-journal', '.damaged')


def is_bag_directory(path: str | Path) -> bool:
    """Whether a directory holds a bag and nothing else (finished, unfinished or empty).

    Parameters
    ----------
    path : str or Path
        A directory.

    Returns
    -------
    bool
        True if every entry is ``metadata.yaml`` or a storage file (``.mcap``,
        ``.db3``, sqlite3's journal files, a ``.damaged`` original kept by
        :func:`maglev_ros.bags.reindex`): safe to replace as a bag.
    """
    path = Path(path)
    return path.is_dir() and all(
        p.is_file() and (p.name == 'metadata.yaml' or p.name.endswith(_BAG_FILE_SUFFIXES))
        for p in path.iterdir()
    )


def decode_metadata(custom: dict[str, str] | None) -> dict[str, object]:
    """Decode ``custom_data`` entries written as YAML scalars (others stay strings).

    Parameters
    ----------
    custom : dict of str to str, optional
        The bag's ``custom_data``.

    Returns
    -------
    dict
        Key to str, int, float, bool or None.
    """
    out: dict[str, object] = {}
    for key, text in (custom or {}).items():
        try:
            value = yaml.safe_load(text) if isinstance(text, str) else text
        except yaml.YAMLError:
            value = text
        out[str(key)] = (
            value if value is None or isinstance(value, (str, int, float, bool)) else text
        )
    return out


def _corrupt(path: Path, exc: BaseException) -> BagError:
    detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    files = (
        [p.name for p in path.iterdir() if p.suffix in _STORAGE_SUFFIXES]
        if path.is_dir()
        else [path.name]
    )
    if not files or detail.startswith('Some database files are missing'):
        return BagError(f'cannot read bag {str(path)!r}: its storage file is missing ({detail})')
    if detail.startswith(_METADATA_ERRORS):
        return BagError(f'cannot read bag {str(path)!r}: its metadata.yaml is invalid ({detail})')
    rebuild = (
        f': rebuild it from its complete messages with maglev-bag2data --reindex --force {path}'
        if path.is_dir()
        else ''
    )
    return BagError(
        f'cannot read bag {str(path)!r}: storage file {", ".join(files)} is '
        f'truncated or corrupt ({detail}){rebuild}'
    )


class BagReader:
    """A rosbag2 bag opened for reading.

    Parameters
    ----------
    path : str or Path
        Bag directory (with ``metadata.yaml``), or a single ``.mcap`` / ``.db3`` file.

    Attributes
    ----------
    path : Path
        The bag.
    storage : str
        ``'mcap'`` or ``'sqlite3'``.
    """

    def __init__(self, path: str | Path) -> None:
        path = Path(path)
        if not path.exists():
            raise BagError(f'bag {str(path)!r} does not exist')
        if path.is_dir():
            files = [p for p in path.iterdir() if not p.name.startswith('.')]
            if not files:
                raise BagError(f'bag directory {str(path)!r} is empty')
            names = sorted(p.name for p in files)
            has_storage = any(suffix in p.name for p in files for suffix in _STORAGE_SUFFIXES)
            if not (path / 'metadata.yaml').is_file() and not has_storage:
                raise BagError(
                    f'{str(path)!r} is not a bag: it has neither metadata.yaml nor a .mcap or '
                    f'.db3 storage file (files: {names})'
                )
            if not (path / 'metadata.yaml').is_file():
                raise BagError(
                    f'bag directory {str(path)!r} has no metadata.yaml (files: '
                    f'{names}); an unfinished recording (a killed recorder) is rebuilt '
                    f'with: maglev-bag2data --reindex {path}'
                )
            storage = next(
                (s for p in files for suf, s in _STORAGE_SUFFIXES.items() if p.name.endswith(suf)),
                '',
            )
        elif path.suffix in _STORAGE_SUFFIXES:
            storage = _STORAGE_SUFFIXES[path.suffix]
        else:
            raise BagError(
                f'{str(path)!r} is not a rosbag2 bag (a directory with '
                f'metadata.yaml, or a .mcap / .db3 file)'
            )
        self.path = path
        self.storage = storage
        self._reader: Reader | None = None
        self._topics: dict[str, TopicInfo] = {}
        self._connections: dict[str, list] = {}
        self._typestore: Typestore | None = None
        self._metadata: dict[str, object] | None = None

    # ------------------------------------------------------------ lifecycle
    def open(self) -> BagReader:
        """Open the bag and read its index.

        Returns
        -------
        BagReader
            ``self``.
        """
        if self._reader is not None:
            raise BagError(f'bag {str(self.path)!r} is open already')
        reader = Reader(self.path)
        try:
            reader.open()
        except (ReaderError, OSError, KeyError, ValueError) as exc:
            raise _corrupt(self.path, exc) from None
        try:
            connections = [c for c in reader.connections]
            if reader.message_count == 0:
                raise BagError(
                    f'bag {str(self.path)!r} is empty: it has no messages '
                    f'(topics: {sorted({c.topic for c in connections})})'
                )
            self._typestore = bag_typestore(connections)
        except BaseException:
            reader.close()
            raise
        self._reader = reader
        for conn in connections:
            name = normalize_topic(conn.topic)
            self._connections.setdefault(name, []).append(conn)
            old = self._topics.get(name)
            self._topics[name] = TopicInfo(
                name, conn.msgtype, conn.msgcount + (old.count if old else 0)
            )
        return self

    def close(self) -> None:
        """Close the bag (idempotent)."""
        reader, self._reader = self._reader, None
        if reader is not None:
            reader.close()

    def __enter__(self) -> BagReader:
        return self.open()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _open_reader(self) -> Reader:
        if self._reader is None:
            raise BagError(f'bag {str(self.path)!r} is not open (use it in a with block)')
        return self._reader

    # -------------------------------------------------------------- content
    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topics by absolute name."""
        self._open_reader()
        return dict(self._topics)

    @property
    def typestore(self) -> Typestore:
        """The type store that knows every message type of the bag."""
        self._open_reader()
        assert self._typestore is not None
        return self._typestore

    @property
    def start_ns(self) -> int:
        """Log time of the first message, ns."""
        return int(self._open_reader().start_time)

    @property
    def end_ns(self) -> int:
        """Log time of the last message, ns."""
        return int(self._open_reader().end_time) - 1

    @property
    def message_count(self) -> int:
        """Number of messages in the bag."""
        return int(self._open_reader().message_count)

    def topic(self, name: str) -> TopicInfo:
        """Return one topic's info; the error lists the topics the bag has.

        Parameters
        ----------
        name : str
            Topic name, with or without the leading ``/``.

        Returns
        -------
        TopicInfo
            The topic.
        """
        self._open_reader()
        key = normalize_topic(name)
        if key not in self._topics:
            have = ', '.join(f'{t} ({i.msgtype})' for t, i in sorted(self._topics.items()))
            raise BagError(f'bag {str(self.path)!r} has no topic {key!r}; its topics: {have}')
        return self._topics[key]

    def deserializer(self, name: str) -> Callable[[bytes], object]:
        """Return a fast deserialiser for the messages of one topic.

        Parameters
        ----------
        name : str
            Topic name.

        Returns
        -------
        callable
            ``f(raw) -> message``.
        """
        return cdr_deserializer(self.typestore, self.topic(name).msgtype)

    def messages(self, topics: Sequence[str]) -> Iterator[tuple[str, int, bytes]]:
        """Iterate over the raw messages of some topics in log-time order.

        Parameters
        ----------
        topics : sequence of str
            Topic names (each must exist).

        Yields
        ------
        tuple of (str, int, bytes)
            Absolute topic name, log time in ns, CDR bytes.
        """
        reader = self._open_reader()
        names = [self.topic(t).name for t in topics]
        connections = [c for n in names for c in self._connections[n]]
        topic_of = {conn.topic: normalize_topic(conn.topic) for conn in connections}
        try:
            for conn, stamp, raw in reader.messages(connections=connections):
                yield topic_of[conn.topic], stamp, raw
        except (ReaderError, OSError, KeyError, ValueError, TypeError) as exc:
            if isinstance(exc, BagError):
                raise
            raise _corrupt(self.path, exc) from None

    @property
    def metadata(self) -> dict[str, object]:
        """Run metadata: ``custom_data`` plus the ``/maglev/metadata`` topic's mapping."""
        reader = self._open_reader()
        if self._metadata is None:
            meta = decode_metadata(
                getattr(reader.storage, 'metadata', None) and reader.storage.metadata.custom
            )
            if METADATA_TOPIC in self._topics:
                decode = self.deserializer(METADATA_TOPIC)
                for _, _, raw in self.messages([METADATA_TOPIC]):
                    try:
                        loaded = yaml.safe_load(getattr(decode(raw), 'data', ''))
                    except yaml.YAMLError:
                        loaded = None
                    if isinstance(loaded, dict):
                        meta.update({str(k): v for k, v in loaded.items()})
            self._metadata = meta
        return dict(self._metadata)
