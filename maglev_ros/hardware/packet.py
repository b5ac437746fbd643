"""V2x solenoid command packets: the encoder and a reference of the board's parser.

A command packet is ten bytes::

    '<'  int16 LE  int16 LE  int16 LE  int16 LE  '>'
    0x3C  x+        x-        y+        y-        0x3E

The board's parser (``CommandParser`` reproduces it byte for byte) ends a
packet at the first ``'>'`` byte and accepts it only with exactly 8 payload
bytes. There is no escaping, so a payload byte equal to ``0x3E`` cannot be
sent. In the PWM range -4096 .. 4096 the high byte of an int16 is one of
0x00 .. 0x10 or 0xF0 .. 0xFF and never 0x3E; only the low byte can collide.
The unsendable values are therefore exactly those with ``v % 256 == 0x3E``:
..., -450, -194, 62, 318, 574, ... (32 values in range). Both neighbours of
such a value are sendable (their low byte is 0x3D or 0x3F), so the nearest
sendable value is one count away; ``sendable_pwm`` picks the neighbour
towards zero (the smaller coil current). Worst-case error: 1 count
(1/4096 of full duty). A ``'<'`` (0x3C) payload byte needs no care: the
parser stores it like any other byte.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    'PACKET_END',
    'PACKET_SIZE',
    'PACKET_START',
    'PAYLOAD_SIZE',
    'PWM_FULL_SCALE',
    'CommandParser',
    'PacketError',
    'decode_command',
    'encode_command',
    'is_sendable',
    'sendable_pwm',
]

PACKET_START = 0x3C  # '<'
PACKET_END = 0x3E  # '>'
PAYLOAD_SIZE = 8  # bytes: four int16 LE
PACKET_SIZE = PAYLOAD_SIZE + 2  # bytes
PWM_FULL_SCALE = 4096  # counts of the 12-bit PWM (full duty)
N_COILS = 4  # x+, x-, y+, y-
#: s without an accepted packet before the board zeroes its PWM (docs/teensy-protocol.md)
WATCHDOG_S = 1.0


class PacketError(ValueError):
    """A command cannot be encoded (wrong shape, type or range)."""


def _as_pwm_counts(name: str, counts: ArrayLike, shape: tuple[int, ...] | None) -> NDArray:
    """Validate integer PWM counts in range and return them as int64."""
    arr = np.asarray(counts)
    if shape is not None and arr.shape != shape:
        raise PacketError(f'{name} must have shape {shape}, got shape {arr.shape}')
    if arr.dtype.kind == 'f':
        if not np.all(np.isfinite(arr)):
            raise PacketError(f'{name} must be finite, got {arr.tolist()}')
        if not np.array_equal(arr, np.round(arr)):
            raise PacketError(f'{name} must be whole PWM counts, got {arr.tolist()}')
    elif arr.dtype.kind not in 'iub':
        raise PacketError(f'{name} must be integer PWM counts, got dtype {arr.dtype}')
    arr = arr.astype(np.int64)
    if np.any(np.abs(arr) > PWM_FULL_SCALE):
        raise PacketError(
            f'{name} must be within -{PWM_FULL_SCALE}..{PWM_FULL_SCALE} counts, got {arr.tolist()}'
        )
    return arr


def is_sendable(counts: ArrayLike) -> NDArray[np.bool_]:
    """Tell which PWM values pass the board's parser unchanged.

    Parameters
    ----------
    counts : array_like of int, any shape
        PWM values in counts, -4096 .. 4096.

    Returns
    -------
    ndarray of bool, same shape
        True where neither byte of the int16 LE encoding is ``'>'`` (0x3E).
    """
    arr = _as_pwm_counts('counts', counts, None)
    raw = arr.astype('<i2').view(np.uint8).reshape(arr.shape + (2,))
    return np.all(raw != PACKET_END, axis=-1)


def sendable_pwm(counts: ArrayLike) -> NDArray[np.int16]:
    """Map PWM values to the nearest values that the board's parser accepts.

    Values whose low byte is 0x3E (``v % 256 == 62``) move one count towards
    zero; every other value in range is returned unchanged. The error is
    therefore at most one count.

    Parameters
    ----------
    counts : array_like of int, any shape
        PWM values in counts, -4096 .. 4096.

    Returns
    -------
    ndarray of int16, same shape
        Sendable PWM values in counts.

    Raises
    ------
    PacketError
        If a value is not a whole number of counts or is out of range.
    """
    arr = _as_pwm_counts('counts', counts, None)
    # High bytes in range are 0x00..0x10 or 0xF0..0xFF, never 0x3E (module docstring).
    bad = (arr & 0xFF) == PACKET_END
    return (arr - np.sign(arr) * bad).astype(np.int16)


def encode_command(counts: ArrayLike) -> bytes:
    """Encode four PWM values as a command packet the board accepts.

    Parameters
    ----------
    counts : array_like of int, shape (4,)
        Signed PWM duties in counts (-4096 .. 4096), order x+, x-, y+, y-.
        Values that cannot pass the parser are replaced by ``sendable_pwm``
        (one count towards zero).

    Returns
    -------
    bytes
        The 10-byte packet ``'<' + 4 x int16 LE + '>'``.

    Raises
    ------
    PacketError
        If ``counts`` does not have shape (4,), is not whole counts, or is out
        of range.
    """
    arr = _as_pwm_counts('counts', counts, (N_COILS,))
    payload = sendable_pwm(arr).astype('<i2').tobytes()
    return bytes((PACKET_START,)) + payload + bytes((PACKET_END,))


def decode_command(payload: bytes) -> tuple[int, int, int, int]:
    """Decode the 8 payload bytes of an accepted packet.

    Parameters
    ----------
    payload : bytes
        Exactly 8 bytes.

    Returns
    -------
    tuple of 4 int
        PWM values in counts, order x+, x-, y+, y-.
    """
    if len(payload) != PAYLOAD_SIZE:
        raise PacketError(f'payload must be {PAYLOAD_SIZE} bytes, got {len(payload)}')
    values = np.frombuffer(payload, dtype='<i2')
    return tuple(int(v) for v in values)  # type: ignore[return-value]


class CommandParser:
    """The V2x board's command parser, byte for byte.

    Bytes are ignored until a ``'<'``; after it every byte (a ``'<'``
    included) is stored until a ``'>'``; the packet is accepted only if
    exactly 8 bytes were stored. When a ninth byte is stored the parser
    resets and waits for the next ``'<'`` (that ninth byte is consumed, even
    if it is a ``'<'``).

    Attributes
    ----------
    accepted : int
        Packets accepted so far.
    discarded : int
        Packets ended by ``'>'`` with a wrong length, or overrun.
    """

    def __init__(self) -> None:
        self._receiving = False
        self._stored = bytearray()
        self.accepted = 0
        self.discarded = 0

    @property
    def receiving(self) -> bool:
        """Whether a ``'<'`` was seen and the parser is storing payload bytes."""
        return self._receiving

    def reset(self) -> None:
        """Return to waiting for ``'<'`` (as after power-up)."""
        self._receiving = False
        self._stored.clear()

    def feed(self, data: Iterable[int]) -> list[tuple[int, int, int, int]]:
        """Parse received bytes.

        Parameters
        ----------
        data : bytes or iterable of int
            Bytes as received from the host.

        Returns
        -------
        list of tuple of 4 int
            The PWM values (counts, x+, x-, y+, y-) of each accepted packet,
            in order.
        """
        accepted = []
        stored = self._stored
        for byte in data:
            if not self._receiving:
                if byte == PACKET_START:
                    self._receiving = True
                    stored.clear()
            elif byte == PACKET_END:
                self._receiving = False
                if len(stored) == PAYLOAD_SIZE:
                    accepted.append(decode_command(bytes(stored)))
                    self.accepted += 1
                else:
                    self.discarded += 1
                stored.clear()
            else:
                stored.append(byte)
                if len(stored) > PAYLOAD_SIZE:
                    self._receiving = False
                    self.discarded += 1
                    stored.clear()
        return accepted
