"""Pull numeric fields and stamps out of one topic's messages, as numpy arrays.

One pass over the bag collects the raw messages of the requested topics (and
only those).  Then, per topic: if all messages share one byte layout (the
usual case: same frame id, names and array lengths), every field is one
strided numpy read over all messages (:mod:`~maglev_ros.cdr.layout`);
otherwise each message is deserialised with the type store's generated CDR
reader and the needed attributes are fetched with one
:func:`operator.attrgetter` call, array indices being applied afterwards on
whole stacked arrays.  Both give the same numbers.
"""

from __future__ import annotations

import gc
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from operator import attrgetter

import numpy as np

from maglev_ros.cdr.layout import cdr_layout, decode_columns

from .channels import FieldRef, check_field, format_field_path
from .command_fields import resolve_ref
from .errors import BagError
from .reader import BagReader

__all__ = ['TopicSamples', 'read_topics']

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


def _stack(objects: Sequence[object]) -> np.ndarray | None:
    """Stack equal-length numeric arrays into one (n, ...) array; None if ragged."""
    try:
        return np.stack(objects)
    except (ValueError, TypeError):
        return None


def _column(
    ref: FieldRef,
    objects: Sequence[object],
    rest: tuple[str | int, ...],
    stacked: np.ndarray | None = None,
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
        if stacked is not None and stacked.ndim > len(indices) and stacked.dtype != object:
            for axis, index in enumerate(indices, start=1):
                if index >= stacked.shape[axis]:
                    raise BagError(
                        f'{ref.text}: index {index} out of range, the messages '
                        f'have {stacked.shape[axis]} elements there'
                    )
            return stacked[(slice(None), *indices)].astype(float)
    out = np.empty(len(objects))
    for n, obj in enumerate(objects):
        try:
            for part in rest:
                obj = obj[part] if isinstance(part, int) else getattr(obj, part)
        except IndexError:
            raise BagError(
                f'{ref.text}: index out of range in message {n} of '
                f'{ref.topic!r} ({format_field_path(ref.path)})'
            ) from None
        out[n] = float(obj)
    return out


def _decode_fast(
    reader: BagReader, msgtype: str, raws: list[bytes], has_header: bool, refs: Sequence[FieldRef]
) -> tuple[np.ndarray | None, np.ndarray] | None:
    """Stamps (or None) and values by strided reads, if all messages share one layout."""
    paths: list[tuple[str | int, ...]] = [ref.path for ref in refs]
    if has_header:
        paths += [('header', 'stamp', 'sec'), ('header', 'stamp', 'nanosec')]
    layout = cdr_layout(reader.typestore, msgtype, raws[0], paths)
    if layout is None:
        return None
    columns = decode_columns(raws, layout, paths)
    if columns is None:
        return None
    values = np.empty((len(raws), len(refs)))
    for k in range(len(refs)):
        values[:, k] = columns[k]
    if not has_header:
        return None, values
    return columns[-2].astype(np.int64) * 1_000_000_000 + columns[-1], values


def _decode_slow(
    reader: BagReader,
    topic: str,
    msgtype: str,
    raws: list[bytes],
    has_header: bool,
    refs: Sequence[FieldRef],
) -> tuple[np.ndarray | None, np.ndarray]:
    """Stamps (or None) and values by deserialising message by message."""
    splits = [_split(ref.path) for ref in refs]
    chains = list(dict.fromkeys(prefix for prefix, _ in splits))
    # '__class__' (unused) keeps the result a tuple when only one attribute is fetched
    fetch = attrgetter(*(_STAMP if has_header else ()), *chains, '__class__')
    deserialize = reader.deserializer(topic)
    # the kept tuples make the cyclic GC rescan a growing heap; nothing here forms cycles
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        rows = [fetch(deserialize(raw)) for raw in raws]
    finally:
        if gc_was_enabled:
            gc.enable()
    columns = list(zip(*rows, strict=True))
    stamps, offset = None, 0
    if has_header:
        offset = 2
        stamps = np.asarray(columns[0], dtype=np.int64) * 1_000_000_000 + np.asarray(
            columns[1], dtype=np.int64
        )
    values = np.empty((len(rows), len(refs)))
    stacks: dict[str, np.ndarray | None] = {}  # one stack per indexed array field
    for k, (ref, (prefix, rest)) in enumerate(zip(refs, splits, strict=True)):
        objects = columns[offset + chains.index(prefix)]
        if rest and all(isinstance(p, int) for p in rest) and prefix not in stacks:
            stacks[prefix] = _stack(objects)
        values[:, k] = _column(ref, objects, rest, stacks.get(prefix))
    return stamps, values


def read_topics(
    reader: BagReader, refs: Mapping[str, Sequence[FieldRef]], fast: bool = True
) -> dict[str, TopicSamples]:
    """Read the stamps and the given fields of every message of some topics, in one pass.

    Parameters
    ----------
    reader : BagReader
        An open bag.
    refs : mapping of str to sequence of FieldRef
        Per topic, the fields to extract (each is checked against the message
        definition before anything is read; a command's ``data[i]`` or
        ``effort[i]`` reads the array the recorded type has, see
        :mod:`~maglev_ros.bags.command_fields`).
    fast : bool
        Decode topics whose messages share one byte layout by strided numpy
        reads (:mod:`~maglev_ros.cdr.layout`); False always deserialises
        message by message (same result, for tests and comparison).

    Returns
    -------
    dict of str to TopicSamples
        Per topic (absolute names, in the order given), stamps and values.

    Raises
    ------
    BagError
        Unknown topic or field, no messages, a truncated storage file.
    """
    infos = {topic: reader.topic(topic) for topic in refs}  # all missing topics first
    # a command's current as the recorded type holds it (data[i] <-> effort[i])
    refs = {t: [resolve_ref(ref, infos[t].msgtype) for ref in refs[t]] for t in refs}
    for topic, info in infos.items():
        for ref in refs[topic]:
            check_field(reader.typestore, info.msgtype, ref)
    log_times: dict[str, list[int]] = {info.name: [] for info in infos.values()}
    raws: dict[str, list[bytes]] = {info.name: [] for info in infos.values()}
    steps = {name: (log_times[name].append, raws[name].append) for name in raws}
    for name, stamp, raw in reader.messages(list(steps)):
        add_time, add_raw = steps[name]
        add_time(stamp)
        add_raw(raw)
    out = {}
    for topic, info in infos.items():
        messages = raws[info.name]
        if not messages:
            raise BagError(f'topic {info.name!r} has no messages in bag {str(reader.path)!r}')
        if len(messages) < info.count:
            raise BagError(
                f'bag {str(reader.path)!r} is truncated: topic {info.name!r} has '
                f'{len(messages)} of the {info.count} messages its index lists'
            )
        has_header = _has_header(reader, info.msgtype)
        decoded = (
            _decode_fast(reader, info.msgtype, messages, has_header, refs[topic]) if fast else None
        )
        if decoded is None:
            decoded = _decode_slow(
                reader, info.name, info.msgtype, messages, has_header, refs[topic]
            )
        header_stamps, values = decoded
        logs = np.asarray(log_times[info.name], dtype=np.int64)
        if header_stamps is not None and np.any(header_stamps):
            out[topic] = TopicSamples(info.name, header_stamps, logs, values, 'header')
        else:
            out[topic] = TopicSamples(info.name, logs, logs, values, 'log')
        raws[info.name] = []  # free the bytes early
    return out
