"""Pull numeric fields and stamps out of one topic's messages, as numpy arrays.

One pass over the topic's raw messages: each is deserialised with the type
store's generated CDR reader and the needed attributes are fetched with one
:func:`operator.attrgetter` call (C speed); array indices are applied
afterwards on whole stacked arrays.  Only the requested topics are read.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from operator import attrgetter

import numpy as np

from .channels import FieldRef, check_field, format_field_path
from .errors import BagError
from .reader import BagReader

__all__ = ['TopicSamples', 'read_topic']

_STAMP = ('header.stamp.sec', 'header.stamp.nanosec')


@dataclass(frozen=True)
class TopicSamples:
    """Fields of every message of one topic.

    Parameters
    ----------
    topic : str
        Absolute topic name.
    stamps : ndarray of int64, shape (n,)
        Header stamps in ns, or log times if the message has no header (or its
        stamps are all zero).
    log_times : ndarray of int64, shape (n,)
        The bag's log (receive) times, ns.
    values : ndarray, shape (n, k)
        One column per requested field, in the order asked.
    clock : {'header', 'log'}
        Where ``stamps`` come from.
    """

    topic: str
    stamps: np.ndarray
    log_times: np.ndarray
    values: np.ndarray
    clock: str


def _has_header(reader: BagReader, msgtype: str) -> bool:
    fields = dict(reader.typestore.fielddefs[msgtype][1])
    header = fields.get('header')
    return header is not None and header[1] == 'std_msgs/msg/Header'


def _split(path: tuple[str | int, ...]) -> tuple[str, tuple[str | int, ...]]:
    """Split a path into its leading dotted attributes and the rest (from the first index)."""
    names: list[str] = []
    for i, part in enumerate(path):
        if isinstance(part, int):
            return '.'.join(names), path[i:]
        names.append(part)
    return '.'.join(names), ()


def _column(ref: FieldRef, objects: Sequence[object], rest: tuple[str | int, ...]
            ) -> np.ndarray:
    """Apply the rest of a path (indices first) to the fetched objects."""
    if not rest:
        return np.asarray(objects, dtype=float)
    indices = []
    for part in rest:
        if not isinstance(part, int):
            break
        indices.append(part)
    if len(indices) == len(rest):
        try:
            stacked = np.stack(objects)
        except ValueError:
            stacked = None  # ragged sequences: element by element below
        if stacked is not None and stacked.ndim > len(indices) and stacked.dtype != object:
            for axis, index in enumerate(indices, start=1):
                if index >= stacked.shape[axis]:
                    raise BagError(f'{ref.text}: index {index} out of range, the messages '
                                   f'have {stacked.shape[axis]} elements there')
            return stacked[(slice(None), *indices)].astype(float)
    out = np.empty(len(objects))
    for n, obj in enumerate(objects):
        try:
            for part in rest:
                obj = obj[part] if isinstance(part, int) else getattr(obj, part)
        except IndexError:
            raise BagError(f'{ref.text}: index out of range in message {n} of '
                           f'{ref.topic!r} ({format_field_path(ref.path)})') from None
        out[n] = float(obj)
    return out


def read_topic(reader: BagReader, topic: str, refs: Sequence[FieldRef]) -> TopicSamples:
    """Read the stamps and the given fields of every message of one topic.

    Parameters
    ----------
    reader : BagReader
        An open bag.
    topic : str
        Topic name.
    refs : sequence of FieldRef
        Fields of this topic (each is checked against the message definition).

    Returns
    -------
    TopicSamples
        Stamps and values.

    Raises
    ------
    BagError
        Unknown topic or field, no messages, a truncated storage file.
    """
    info = reader.topic(topic)
    for ref in refs:
        check_field(reader.typestore, info.msgtype, ref)
    has_header = _has_header(reader, info.msgtype)
    splits = [_split(ref.path) for ref in refs]
    chains = list(dict.fromkeys(prefix for prefix, _ in splits))
    getter = attrgetter(*(_STAMP if has_header else ()), *chains, '__class__')
    deserialize = reader.deserializer(info.name)
    log_times: list[int] = []
    records: list[tuple] = []
    append_time, append_record = log_times.append, records.append
    for _, stamp, raw in reader.messages([info.name]):
        append_time(stamp)
        append_record(getter(deserialize(raw)))
    if not records:
        raise BagError(f'topic {info.name!r} has no messages in bag {str(reader.path)!r}')
    if len(records) < info.count:
        raise BagError(f'bag {str(reader.path)!r} is truncated: topic {info.name!r} has '
                       f'{len(records)} of the {info.count} messages its index lists')
    columns = list(zip(*records, strict=True))
    logs = np.asarray(log_times, dtype=np.int64)
    clock = 'log'
    stamps = logs
    offset = 0
    if has_header:
        offset = 2
        sec = np.asarray(columns[0], dtype=np.int64)
        nsec = np.asarray(columns[1], dtype=np.int64)
        if np.any(sec) or np.any(nsec):
            stamps, clock = sec * 1_000_000_000 + nsec, 'header'
    values = np.empty((len(records), len(refs)))
    for k, (ref, (prefix, rest)) in enumerate(zip(refs, splits, strict=True)):
        values[:, k] = _column(ref, columns[offset + chains.index(prefix)], rest)
    return TopicSamples(info.name, stamps, logs, values, clock)
