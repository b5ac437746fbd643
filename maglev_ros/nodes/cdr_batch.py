"""Serialised messages without message objects: the layout of a message's CDR bytes.

Publishing a message object costs a Python-to-C conversion and a
serialisation per message; publishing bytes (``Publisher.publish(bytes)``)
costs neither. The messages on the Maggy graph that go out at 5 kHz differ
from sample to sample only in their stamp and a few float64 fields, so a
template is serialised once with sentinel values, the byte offsets of the
stamp and of each varying float64 are found from the sentinels
(:func:`cdr_layout`), and messages are made by patching those bytes:

* one at a time with ``struct`` (:class:`maglev_ros.nodes.contract.RawTemplate`);
* a burst of samples at once with numpy (:class:`RawMessageBatch` for one
  message type, :class:`SampleSerialiser` for several per sample, e.g. the
  field of each sensor and the currents), what the driver and the real-time
  simulator publish every millisecond.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from rclpy.serialization import serialize_message

__all__ = ['CdrLayout', 'RawMessageBatch', 'SampleSerialiser', 'cdr_layout']

_SEC, _NANOSEC = 0x1234_5678, 0x2345_6789  # stamp sentinels


@dataclass(frozen=True)
class CdrLayout:
    """Where the varying parts of a message sit in its CDR bytes.

    Attributes
    ----------
    template : bytes
        The serialised template (4-byte little-endian CDR encapsulation first).
    stamp_offset : int
        Byte offset of the stamp's ``sec`` (int32); ``nanosec`` (uint32) follows.
    value_offsets : tuple of int
        Byte offset of each varying float64, in the order of ``set_values``.
    """

    template: bytes
    stamp_offset: int
    value_offsets: tuple[int, ...]


def cdr_layout(template, set_values: Callable, n_values: int,
               stamp: Callable | None = None) -> CdrLayout:
    """Serialise ``template`` with sentinels and locate its stamp and varying float64s.

    Parameters
    ----------
    template : message
        A message with the constant parts (frame ids, names, array lengths)
        set; it is modified (sentinels written).
    set_values : callable
        ``set_values(msg, values)`` writes ``n_values`` floats into the message.
    n_values : int
        Number of varying float64 fields (>= 0).
    stamp : callable, optional
        ``stamp(msg)`` returns the ``builtin_interfaces/Time`` that varies
        (default ``msg.header.stamp``).

    Returns
    -------
    CdrLayout

    Raises
    ------
    ValueError
        If the bytes are not little-endian CDR, or a field cannot be located
        unambiguously.
    """
    time = (stamp or (lambda m: m.header.stamp))(template)
    time.sec, time.nanosec = _SEC, _NANOSEC
    sentinels = [1.2345678901234567e-300 * (j + 3) for j in range(n_values)]
    if n_values:
        set_values(template, sentinels)
    raw = bytes(serialize_message(template))
    if raw[:2] != b'\x00\x01':  # not little-endian CDR: not supported
        raise ValueError(f'unexpected CDR encapsulation {raw[:4].hex()}')

    def find(pattern: bytes) -> int:
        offset = raw.find(pattern)
        if offset < 0 or raw.find(pattern, offset + 1) >= 0:
            raise ValueError('cannot locate a field in the serialised template')
        return offset

    stamp_offset = find(struct.pack('<i', _SEC))
    if find(struct.pack('<I', _NANOSEC)) != stamp_offset + 4:
        raise ValueError('stamp sec and nanosec are not adjacent')
    return CdrLayout(raw, stamp_offset, tuple(find(struct.pack('<d', v)) for v in sentinels))


class RawMessageBatch:
    """Serialise many messages of one type that differ only in stamp and float64s.

    Parameters
    ----------
    template : message
        A message with the constant parts (frame id, names, array lengths)
        set; it is modified (sentinels written).
    set_values : callable
        ``set_values(msg, values)`` writes a sequence of k floats into the
        message (the varying float64 fields).
    n_values : int
        k, the number of varying float64 fields.
    """

    def __init__(self, template, set_values: Callable, n_values: int) -> None:
        layout = cdr_layout(template, set_values, n_values)
        doubles = list(layout.value_offsets)
        names = ['sec', 'nanosec']
        formats = ['<i4', '<u4']
        offsets = [layout.stamp_offset, layout.stamp_offset + 4]
        if doubles == list(range(doubles[0], doubles[0] + 8 * n_values, 8)):
            names.append('values')  # contiguous (x, y, z; effort): one assignment
            formats.append(('<f8', (n_values,)))
            offsets.append(doubles[0])
        else:
            names += [f'v{j}' for j in range(n_values)]
            formats += ['<f8'] * n_values
            offsets += doubles
        # A structured view of one serialised message: numpy writes the
        # (possibly unaligned) stamp and float64 fields in place.
        self._dtype = np.dtype(
            {'names': names, 'formats': formats, 'offsets': offsets,
             'itemsize': len(layout.template)}
        )
        self._template = np.frombuffer(layout.template, dtype=np.uint8)
        self.size = len(layout.template)
        self._alone: SampleSerialiser | None = None  # for serialise()

    def serialise(self, sec: np.ndarray, nanosec: np.ndarray, values: np.ndarray) -> list[bytes]:
        """Serialise n messages.

        Parameters
        ----------
        sec, nanosec : ndarray of int, shape (n,)
            Header stamps.
        values : ndarray of float, shape (n, k)
            The varying float64 fields, in the order of ``set_values``.

        Returns
        -------
        list of bytes
            n serialised messages.
        """
        if self._alone is None:
            self._alone = SampleSerialiser([self])
        return self._alone.serialise(sec, nanosec, [values])


class SampleSerialiser:
    """Serialise, per sample, one message of each of several layouts in one go.

    Parameters
    ----------
    parts : list of RawMessageBatch
        The message layouts of one sample (e.g. the field of each sensor,
        then the currents); all share the sample's stamp.
    """

    def __init__(self, parts: list[RawMessageBatch]) -> None:
        names, formats, offsets = [], [], []
        base = 0
        self._fields = []
        for p, part in enumerate(parts):
            layout = part._dtype
            for name in layout.names:
                fmt, offset = layout.fields[name][:2]
                names.append(f'{p}:{name}')
                formats.append(fmt)
                offsets.append(base + offset)
            self._fields.append([f'{p}:{name}' for name in layout.names])
            base += part.size
        self._dtype = np.dtype(
            {'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': base}
        )
        self._template = np.concatenate([part._template for part in parts])
        self._sizes = [part.size for part in parts]
        self.size = base
        self._rows: dict[int, np.ndarray] = {}  # per n: rows holding the template (reused)
        self._bounds: dict[int, list[tuple[int, int]]] = {}  # per n: (start, end) of messages

    def serialise(
        self, sec: np.ndarray, nanosec: np.ndarray, values: list[np.ndarray]
    ) -> list[bytes]:
        """Serialise n samples.

        Parameters
        ----------
        sec, nanosec : ndarray of int, shape (n,)
            Header stamps.
        values : list of ndarray, one per part, shape (n, k_part)
            The varying float64 fields of each part.

        Returns
        -------
        list of bytes
            n * len(parts) messages, sample by sample, parts in order.
        """
        n = sec.shape[0]
        rows = self._rows.get(n)
        if rows is None:
            # the template's constant bytes are written once; every call overwrites all
            # varying fields (stamps, values), so the rows can be reused
            rows = np.empty(n, dtype=self._dtype)
            rows.view(np.uint8).reshape(n, self.size)[:] = self._template
            ends = np.cumsum(np.tile(self._sizes, n)).tolist()
            self._bounds[n] = list(zip([0] + ends[:-1], ends, strict=True))
            if len(self._rows) < 64:  # bursts have a few typical lengths
                self._rows[n] = rows
        for fields, part_values in zip(self._fields, values, strict=True):
            rows[fields[0]] = sec
            rows[fields[1]] = nanosec
            if len(fields) == 3:
                rows[fields[2]] = part_values
            else:
                for j, name in enumerate(fields[2:]):
                    rows[name] = part_values[:, j]
        data = rows.tobytes()
        return [data[start:end] for start, end in self._bounds[n]]
