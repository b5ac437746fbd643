"""Rebuild an unfinished bag (``ros2 bag reindex`` for the bags maglev_ros records).

A recording killed with SIGKILL or by a power loss leaves a bag directory
without ``metadata.yaml`` and, for MCAP, a file without its summary, possibly
cut inside a record. :func:`reindex` salvages every complete message from the
storage file (MCAP records and chunks in file order, stopping at the first
incomplete one; sqlite3: the committed rows) and writes a finished bag in its
place; the original file is kept beside it as ``<name>.damaged``. The
recorder's writer flushes every second (:data:`maglev_ros.bags.writer.FLUSH_PERIOD_S`),
so at most about the last second of a recording is lost.

Topics whose message type is not in ROS 2 Jazzy's standard set cannot be
re-serialised here and are skipped (named in the report). The run metadata of
the original ``metadata.yaml`` is gone; the rebuilt bag's metadata says it was
reindexed, from which file, and how many bytes at the end were not salvaged.
"""

from __future__ import annotations

import shutil
import sqlite3
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path

from .errors import BagError
from .names import normalize_msgtype
from .typestore import jazzy_typestore
from .writer import BagWriter

__all__ = ['ReindexReport', 'Salvage', 'reindex', 'salvage_mcap', 'salvage_sqlite3']

_MAGIC = b'\x89MCAP0\r\n'
_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_RECORD = struct.Struct('<BQ')  # opcode, content length
_MESSAGE = struct.Struct('<HIQQ')  # channel id, sequence, log time, publish time
_SCHEMA, _CHANNEL, _MESSAGE_OP, _CHUNK, _DATA_END = 0x03, 0x04, 0x05, 0x06, 0x0F


@dataclass(frozen=True)
class Salvage:
    """What a damaged storage file still holds.

    Attributes
    ----------
    topics : dict
        Topic name -> message type (``pkg/msg/Type``).
    messages : list of tuple
        ``(topic, log time ns, CDR bytes)``, in file order.
    intact_bytes : int
        Length of the readable part of the file (MCAP), or its size (sqlite3).
    file_bytes : int
        Size of the file.
    """

    topics: dict[str, str]
    messages: list[tuple[str, int, bytes]]
    intact_bytes: int
    file_bytes: int


@dataclass(frozen=True)
class ReindexReport:
    """Result of :func:`reindex`.

    Attributes
    ----------
    path : Path
        The bag directory (now finished).
    storage : str
        ``mcap`` or ``sqlite3``.
    counts : dict
        Messages per topic in the rebuilt bag.
    skipped : dict
        Topics not rebuilt -> their message type (not a standard type).
    damaged : Path
        The original storage file, kept.
    lost_bytes : int
        Bytes at the end of the original file that held no complete record.
    """

    path: Path
    storage: str
    counts: dict[str, int]
    skipped: dict[str, str]
    damaged: Path
    lost_bytes: int

    def describe(self) -> str:
        """One line for people."""
        total = sum(self.counts.values())
        text = (
            f'{self.path}: rebuilt from {self.damaged.name} ({self.storage}): {total} '
            f'messages on {len(self.counts)} topic(s); {self.lost_bytes} trailing bytes '
            f'held no complete record'
        )
        if self.skipped:
            text += f'; skipped (not standard types): {sorted(self.skipped)}'
        return text


def _string(buf: bytes, at: int) -> tuple[str, int]:
    (n,) = _U32.unpack_from(buf, at)
    end = at + 4 + n
    if end > len(buf):
        raise struct.error('string past the record')
    return buf[at + 4 : end].decode(), end


def _records(buf: bytes, at: int, end: int):
    """Yield ``(opcode, start, stop)`` of the complete records in ``buf[at:end]``."""
    while at + _RECORD.size <= end:
        opcode, length = _RECORD.unpack_from(buf, at)
        start = at + _RECORD.size
        if start + length > end:
            return
        yield opcode, start, start + length
        at = start + length


def salvage_mcap(path: str | Path) -> Salvage:
    """Read every complete message of an MCAP file, summary or not.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file (possibly cut off anywhere).

    Returns
    -------
    Salvage
    """
    buf = Path(path).read_bytes()
    if not buf.startswith(_MAGIC):
        raise BagError(f'{str(path)!r} is not an MCAP file (no MCAP magic at its start)')
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    messages: list[tuple[str, int, bytes]] = []
    intact = len(_MAGIC)

    def take(data: bytes, opcode: int, start: int, stop: int) -> None:
        if opcode == _SCHEMA:
            (sid,) = _U16.unpack_from(data, start)
            name, _ = _string(data, start + 2)
            schemas[sid] = normalize_msgtype(name)
        elif opcode == _CHANNEL:
            cid, sid = struct.unpack_from('<HH', data, start)
            topic, _ = _string(data, start + 4)
            channels[cid] = (topic, schemas.get(sid, ''))
        elif opcode == _MESSAGE_OP:
            cid, _, log_time, _ = _MESSAGE.unpack_from(data, start)
            if cid in channels:
                messages.append((channels[cid][0], log_time, data[start + _MESSAGE.size : stop]))

    for opcode, start, stop in _records(buf, len(_MAGIC), len(buf)):
        if opcode == _DATA_END:
            intact = stop
            break
        if opcode == _CHUNK:
            at = start + 8 + 8 + 8 + 4  # start/end time, uncompressed size, crc
            try:
                compression, at = _string(buf, at)
                (size,) = _U64.unpack_from(buf, at)
            except struct.error:
                break
            body = buf[at + 8 : at + 8 + size]
            if compression == 'zstd':
                import zstandard

                body = zstandard.ZstdDecompressor().decompress(body)
            elif compression:
                raise BagError(f'{str(path)!r}: chunk compression {compression!r} not supported')
            for record in _records(body, 0, len(body)):
                take(body, *record)
        else:
            take(buf, opcode, start, stop)
        intact = stop
    topics = {topic: msgtype for topic, msgtype in channels.values()}
    return Salvage(topics, messages, intact, len(buf))


def salvage_sqlite3(path: str | Path) -> Salvage:
    """Read every committed message of a rosbag2 sqlite3 file.

    Parameters
    ----------
    path : str or Path
        The ``.db3`` file.

    Returns
    -------
    Salvage
    """
    size = Path(path).stat().st_size
    try:
        conn = sqlite3.connect(f'file:{path}', uri=True)
        try:
            rows = conn.execute('SELECT id, name, type FROM topics').fetchall()
            names = {tid: name for tid, name, _ in rows}
            messages = [
                (names[tid], int(stamp), bytes(data))
                for tid, stamp, data in conn.execute(
                    'SELECT topic_id, timestamp, data FROM messages ORDER BY id'
                )
                if tid in names
            ]
        finally:
            conn.close()
    except sqlite3.DatabaseError as err:
        raise BagError(f'{str(path)!r} is not a readable rosbag2 sqlite3 file: {err}') from None
    topics = {name: normalize_msgtype(msgtype) for _, name, msgtype in rows}
    return Salvage(topics, messages, size, size)


def _run_metadata(metadata: Path) -> dict[str, object]:
    """Read the run metadata (``custom_data``) of a ``metadata.yaml``; empty if unreadable."""
    import yaml

    try:
        info = yaml.safe_load(metadata.read_text(encoding='utf-8'))
        custom = info['rosbag2_bagfile_information'].get('custom_data') or {}
        values = {str(k): yaml.safe_load(str(v)) for k, v in custom.items()}
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return {}
    return {k: v for k, v in values.items() if isinstance(v, (str, int, float, bool))}


def reindex(path: str | Path, force: bool = False) -> ReindexReport:
    """Rebuild an unfinished bag in place (see the module docstring).

    Parameters
    ----------
    path : str or Path
        A bag directory without ``metadata.yaml``.
    force : bool
        Rebuild a bag that has a ``metadata.yaml`` too (a finished bag whose
        storage file was cut afterwards, by a full disk or a copy): its run
        metadata is kept, the old file stays beside it as
        ``metadata.yaml.damaged``.

    Returns
    -------
    ReindexReport

    Raises
    ------
    BagError
        If the bag is finished already, holds no storage file, or nothing in it
        can be salvaged.
    """
    bag = Path(path)
    if not bag.is_dir():
        raise BagError(f'bag {str(bag)!r} is not a directory')
    metadata = bag / 'metadata.yaml'
    if metadata.is_file() and not force:
        raise BagError(
            f'bag {str(bag)!r} is finished (it has metadata.yaml): nothing to rebuild; if its '
            f'storage file is truncated, rebuild it anyway with maglev-bag2data --reindex '
            f'--force {bag}'
        )
    files = sorted([*bag.glob('*.mcap'), *bag.glob('*.db3')])
    if not files:
        names = sorted(p.name for p in bag.iterdir())
        raise BagError(
            f'{str(bag)!r} is not a bag: it holds no .mcap or .db3 storage file to rebuild '
            f'(files: {names})'
        )
    if len(files) != 1:
        raise BagError(
            f'bag {str(bag)!r} must hold one .mcap or .db3 file to rebuild, found '
            f'{[f.name for f in files]}'
        )
    source = files[0]
    storage = 'mcap' if source.suffix == '.mcap' else 'sqlite3'
    found = salvage_mcap(source) if storage == 'mcap' else salvage_sqlite3(source)
    known = jazzy_typestore().fielddefs
    skipped = {t: m for t, m in found.topics.items() if m not in known}
    kept = {t: m for t, m in found.topics.items() if t not in skipped}
    if not any(topic in kept for topic, _, _ in found.messages):
        raise BagError(
            f'bag {str(bag)!r}: no complete message of a standard type in {source.name} '
            f'(topics: {found.topics})'
        )
    lost = found.file_bytes - found.intact_bytes
    work = Path(tempfile.mkdtemp(prefix='.reindex-', dir=bag.parent))
    try:
        rebuilt = work / bag.name
        meta: dict[str, object] = {
            **(_run_metadata(metadata) if metadata.is_file() else {}),
            'reindexed_from': source.name,
            'reindex_lost_bytes': lost,
        }
        counts = dict.fromkeys(kept, 0)
        with BagWriter(rebuilt, storage, metadata=meta) as writer:
            handles = {topic: writer.add_topic(topic, msgtype) for topic, msgtype in kept.items()}
            for topic, stamp, data in sorted(found.messages, key=lambda m: m[1]):
                if topic in handles:
                    writer.write(handles[topic], stamp, data)
                    counts[topic] += 1
        damaged = source.with_name(source.name + '.damaged')
        source.rename(damaged)
        if metadata.is_file():
            metadata.rename(metadata.with_name(metadata.name + '.damaged'))
        for journal in bag.glob(source.name + '-*'):  # sqlite3 -wal / -shm / -journal
            journal.rename(journal.with_name(journal.name + '.damaged'))
        for item in rebuilt.iterdir():
            shutil.move(str(item), bag / item.name)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return ReindexReport(bag, storage, counts, skipped, damaged, lost)
