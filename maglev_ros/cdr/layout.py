"""Byte offsets of message fields in CDR, to decode many equal-layout messages at once.

A topic's messages usually share one byte layout: the same frame id, joint
names and array lengths give every field the same offset.  :func:`cdr_layout`
walks the first (little-endian) message once and records the offset and dtype
of the wanted fields and the offset and value of every string or sequence
length on the way.  :func:`decode_columns` then checks that every message has
the same size, encapsulation header and lengths; in CDR the offsets follow
from the lengths met in order, so the messages then share the layout exactly
and each field is one strided numpy read over all messages.  Anything else
(big-endian data, ``wstring``, differing lengths) returns None, and the caller
deserialises message by message instead.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

__all__ = ['CdrLayout', 'Path', 'cdr_layout', 'decode_columns']

Path = tuple[str | int, ...]  # a field path: names and sequence indices
# ROS 2 primitive -> little-endian numpy dtype (char and byte are uint8 in ROS 2)
_DTYPES = {
    'bool': '|u1',
    'byte': '|u1',
    'char': '|u1',
    'octet': '|u1',
    'int8': '|i1',
    'uint8': '|u1',
    'int16': '<i2',
    'uint16': '<u2',
    'int32': '<i4',
    'uint32': '<u4',
    'int64': '<i8',
    'uint64': '<u8',
    'float32': '<f4',
    'float64': '<f8',
}
_HEADER = 4  # CDR encapsulation header, bytes


class _LayoutError(Exception):
    """The message cannot be laid out (wstring, corrupt lengths)."""


@dataclass(frozen=True)
class CdrLayout:
    """Where the wanted fields sit in messages shaped like the first one.

    Parameters
    ----------
    size : int
        Message size in bytes, with the encapsulation header.
    lengths : tuple of (int, int)
        Offset and value of every string and sequence length field (uint32).
    fields : dict
        Field path -> (byte offset, numpy dtype string).
    """

    size: int
    lengths: tuple[tuple[int, int], ...]
    fields: dict[Path, tuple[int, str]]


class _Walker:
    def __init__(self, typestore: Typestore, raw: bytes, wanted: Collection[Path]) -> None:
        self.store, self.raw, self.wanted = typestore, raw, set(wanted)
        self.pos = 0  # relative to the payload, which is what CDR alignment counts from
        self.lengths: list[tuple[int, int]] = []
        self.fields: dict[Path, tuple[int, str]] = {}

    def align(self, size: int) -> None:
        self.pos = (self.pos + size - 1) & -size

    def length(self) -> int:
        self.align(4)
        start = _HEADER + self.pos
        if start + 4 > len(self.raw):
            raise _LayoutError
        value = int.from_bytes(self.raw[start : start + 4], 'little')
        self.lengths.append((start, value))
        self.pos += 4
        return value

    def message(self, msgtype: str, path: Path) -> None:
        for name, desc in self.store.fielddefs[msgtype][1]:
            self.node(desc, (*path, name))

    def node(self, desc: tuple, path: Path) -> None:
        kind, detail = desc
        if kind == Nodetype.NAME:
            self.message(detail, path)
        elif kind == Nodetype.BASE:
            self.base(detail[0], path)
        else:
            sub, count = detail
            if kind == Nodetype.SEQUENCE:
                count = self.length()
            if sub[0] == Nodetype.BASE and sub[1][0] in _DTYPES:
                self.primitives(sub[1][0], count, path)
            else:
                for i in range(count):
                    self.node(sub, (*path, i))

    def base(self, typename: str, path: Path) -> None:
        if typename == 'string':
            size = self.length()  # (not pos += length(): that would add to the old pos)
            self.pos += size
            return
        if typename not in _DTYPES:
            raise _LayoutError
        self.primitives(typename, 1, path, scalar=True)

    def primitives(self, typename: str, count: int, path: Path, scalar: bool = False) -> None:
        dtype = _DTYPES[typename]
        size = int(dtype[2:])
        if count:
            self.align(size)
        start = _HEADER + self.pos
        if scalar:
            if path in self.wanted:
                self.fields[path] = (start, dtype)
        else:
            for want in self.wanted:
                if (
                    len(want) == len(path) + 1
                    and want[:-1] == path
                    and isinstance(want[-1], int)
                    and want[-1] < count
                ):
                    self.fields[want] = (start + want[-1] * size, dtype)
        self.pos += count * size
        if _HEADER + self.pos > len(self.raw):
            raise _LayoutError


def cdr_layout(
    typestore: Typestore, msgtype: str, raw: bytes, wanted: Collection[Path]
) -> CdrLayout | None:
    """Lay out one little-endian CDR message and locate the wanted fields.

    Parameters
    ----------
    typestore : rosbags Typestore
        Store that knows ``msgtype``.
    msgtype : str
        Message type.
    raw : bytes
        One message with its 4-byte encapsulation header.
    wanted : collection of tuple
        Field paths (names and indices) of numeric fields.

    Returns
    -------
    CdrLayout or None
        None if the message is big-endian, uses ``wstring``, is shorter than its
        lengths say, or a wanted field is not in it (e.g. an index beyond a
        sequence's length).
    """
    if len(raw) < _HEADER or raw[0] != 0 or raw[1] != 1:
        return None
    walker = _Walker(typestore, raw, wanted)
    try:
        walker.message(msgtype, ())
    except _LayoutError:
        return None
    if set(walker.fields) != set(wanted):
        return None
    return CdrLayout(len(raw), tuple(walker.lengths), walker.fields)


def _column(block: np.ndarray, offset: int, dtype: str) -> np.ndarray:
    size = np.dtype(dtype).itemsize
    return np.ascontiguousarray(block[:, offset : offset + size]).view(dtype)[:, 0]


def decode_columns(
    raws: Sequence[bytes], layout: CdrLayout, paths: Sequence[Path]
) -> list[np.ndarray] | None:
    """Decode fields of many messages at once, if they all share ``layout``.

    Parameters
    ----------
    raws : sequence of bytes
        Messages (with their encapsulation headers), all of one type.
    layout : CdrLayout
        The layout of the first one.
    paths : sequence of tuple
        Fields to decode (each in ``layout.fields``).

    Returns
    -------
    list of ndarray or None
        One array of shape (n,) per path, in its own dtype; None if some
        message does not share the layout.
    """
    size = layout.size
    if any(len(raw) != size for raw in raws):
        return None
    block = np.frombuffer(b''.join(raws), dtype=np.uint8).reshape(len(raws), size)
    if np.any(block[:, 0] != 0) or np.any(block[:, 1] != 1):
        return None
    for offset, value in layout.lengths:
        if np.any(_column(block, offset, '<u4') != value):
            return None
    return [_column(block, *layout.fields[path]) for path in paths]
