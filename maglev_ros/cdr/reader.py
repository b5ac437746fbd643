"""Read the stamp and a few numeric fields of single raw CDR messages, fast.

A node that receives 5 kHz streams spends most of its time turning each
message into a Python object (rclpy's deserialisation: about 35-45 us for a
``sensor_msgs/MagneticField``, against 15 us for taking the raw bytes). A
:class:`RawFieldReader` lays out the first message of a topic once
(:func:`~maglev_ros.cdr.layout.cdr_layout`) and then reads every message of
the same layout with one ``struct`` call: the header stamp, the wanted
fields, and every string and sequence length on the way, which must equal
the first message's (in CDR the offsets follow from those lengths, so equal
lengths mean equal offsets). A message of another layout (a different frame
id, more joints) is laid out again; one that cannot be laid out (big-endian,
a wanted field missing) gives None.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from .layout import Path, cdr_layout
from .templates import HEADER_STAMP
from .typestore import jazzy_typestore

__all__ = ['RawFieldReader']

_CODES = {'<f8': 'd', '<f4': 'f', '<i4': 'i', '<u4': 'I', '<i8': 'q', '<u8': 'Q'}


class RawFieldReader:
    """Decode ``header.stamp`` and numeric fields of raw messages of one type.

    Parameters
    ----------
    msgtype : str
        Message type, ``pkg/msg/Type`` (e.g. ``sensor_msgs/msg/MagneticField``).
    paths : sequence of tuple
        Field paths of the numeric fields to read, e.g. ``('magnetic_field', 'x')``
        or ``('effort', 2)``.
    stamp : tuple or None, optional
        Path of the stamp (default the header's; None: a message without one,
        e.g. ``std_msgs/msg/Float64MultiArray``).

    Attributes
    ----------
    layouts : int
        Layouts computed so far (1 for a topic whose messages share one).

    Examples
    --------
    >>> from maglev_ros.cdr import FIELD_VALUES
    >>> reader = RawFieldReader('sensor_msgs/msg/MagneticField', FIELD_VALUES)
    >>> reader.read(raw)  # doctest: +SKIP
    (1200000, (1.2e-05, -3.0e-06, 0.0211))
    """

    def __init__(
        self, msgtype: str, paths: Sequence[Path], stamp: Path | None = HEADER_STAMP
    ) -> None:
        self.msgtype = msgtype
        self.paths = tuple(tuple(p) for p in paths)
        self._stamped = stamp is not None
        stamps = [(*stamp, 'sec'), (*stamp, 'nanosec')] if stamp is not None else []
        self._wanted = [*stamps, *self.paths]
        self._store = jazzy_typestore()
        self._struct: struct.Struct | None = None
        self._size = -1
        self._lengths: tuple[int, ...] = ()  # every length field's value, in byte order
        self._length_positions: list[int] = []  # their positions in the unpacked tuple
        self._order: list[int] = []  # position of each wanted field in the unpacked tuple
        self.layouts = 0

    def _lay_out(self, raw: bytes) -> bool:
        layout = cdr_layout(self._store, self.msgtype, raw, self._wanted)
        if layout is None:
            return False
        items = [(offset, '<u4', None) for offset, _ in layout.lengths]
        items += [(*layout.fields[w], i) for i, w in enumerate(self._wanted)]
        items.sort(key=lambda item: item[0])
        fmt, at, order = '<', 0, [0] * len(self._wanted)
        lengths = [value for _, value in layout.lengths]
        for position, (offset, dtype, wanted) in enumerate(items):
            code = _CODES.get(dtype)
            if code is None or offset < at:
                return False
            fmt += f'{offset - at}x' if offset > at else ''
            fmt += code
            at = offset + struct.calcsize('<' + code)
            if wanted is not None:
                order[wanted] = position
        self._struct = struct.Struct(fmt)
        self._size = layout.size
        self._length_positions = [i for i, item in enumerate(items) if item[2] is None]
        self._lengths = tuple(lengths)
        self._order = order
        self.layouts += 1
        return True

    def read(self, raw: bytes) -> tuple[int | None, tuple[float, ...]] | None:
        """Return ``(stamp_ns, values)`` of one message, or None if it cannot be read.

        Parameters
        ----------
        raw : bytes
            The message with its 4-byte encapsulation header (what a
            ``raw=True`` subscription delivers).

        Returns
        -------
        tuple of (int or None, tuple of float) or None
            The stamp in ns (None without a stamp path) and the values of
            ``paths``, in order; None for a message that cannot be laid out
            (big-endian, a field missing).
        """
        values = self._unpack(raw)
        if values is None and self._lay_out(raw):  # another layout: walk it once
            values = self._unpack(raw)
        if values is None:
            return None
        order = self._order
        if not self._stamped:
            return None, tuple(values[i] for i in order)
        return values[order[0]] * 1_000_000_000 + values[order[1]], tuple(
            values[i] for i in order[2:]
        )

    def _unpack(self, raw: bytes) -> tuple | None:
        """Unpack ``raw`` by the current layout, None if it does not have it."""
        if self._struct is None or len(raw) != self._size or raw[1] != 1:
            return None
        values = self._struct.unpack_from(raw)
        if tuple(values[i] for i in self._length_positions) != self._lengths:
            return None
        return values
