"""The V4x PC-control firmware's messages: requests, replies, and the wire order.

The host sends one COBS frame (:mod:`.cobs_frame`) and the board answers
with one; payloads before encoding, little-endian, float32 (docs/boards.md)::

    request           reply payload
    01 read sensors   01 + Bx By Bz (mT) dBx dBy dBz (mT/s), 6 x float32 (25 bytes)
    02 read currents  02 + 4 x float32 (A), wire order x+ y- x- y+      (17 bytes)
    03 a b c d        03; a b c d: uint8 PWM magnitudes, wire order x+ y- x- y+
    04 reset          04; all coils at PWM 0
    05 status         05 04 09 + uint16 uptime (s)
    AA ping           the single raw byte EE (no COBS, no delimiter)
    anything else     00 67 (error, code 103)

**Order.** The firmware's wire order of the four coils is **x+, y-, x-, y+**;
everywhere else in this package (commands, ROS messages, emulators) the
order is **x+, x-, y+, y-**. :func:`to_wire` and :func:`from_wire` convert.

**Set currents.** The board drives each pair antisymmetrically:
``p_x = a - c`` goes to x+ and ``-p_x`` to x-, ``p_y = d - b`` to y+ and
``-p_y`` to y-. Only the two differences reach the coils, so a request is
built from them (:func:`set_pwm_request`), with ``a = max(0, p_x)``,
``c = max(0, -p_x)`` and likewise ``d``, ``b`` for y.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .cobs_frame import encode_frame

__all__ = [
    'ERROR_UNKNOWN_REQUEST',
    'PING',
    'PING_REPLY',
    'PWM_MAX',
    'READ_CURRENTS',
    'READ_SENSORS',
    'RESET',
    'SET_PWM',
    'STATUS',
    'AckReply',
    'CurrentsReply',
    'ErrorReply',
    'ProtocolError',
    'Reply',
    'SensorsReply',
    'StatusReply',
    'applied_pwm',
    'currents_payload',
    'decode_reply',
    'error_payload',
    'from_wire',
    'pair_magnitudes',
    'request',
    'sensors_payload',
    'set_pwm_request',
    'status_payload',
    'to_wire',
]

READ_SENSORS = 0x01
READ_CURRENTS = 0x02
SET_PWM = 0x03
RESET = 0x04
STATUS = 0x05
PING = 0xAA
PING_REPLY = 0xEE
ERROR = 0x00
ERROR_UNKNOWN_REQUEST = 103  # the firmware's only error code
STATUS_SOLENOIDS, STATUS_SENSORS = 4, 9  # the constant bytes of the status reply
PWM_MAX = 255  # largest |pair difference|: 8-bit PWM

# ours (x+, x-, y+, y-) -> wire (x+, y-, x-, y+), and back
_TO_WIRE = np.array([0, 3, 1, 2])
_FROM_WIRE = np.array([0, 2, 3, 1])
_REPLY_SIZE = {READ_SENSORS: 25, READ_CURRENTS: 17, SET_PWM: 1, RESET: 1, STATUS: 5}


class ProtocolError(ValueError):
    """A reply that does not fit its request, or a request that cannot be built."""


def to_wire(values: ArrayLike) -> NDArray:
    """Reorder four per-coil values from x+, x-, y+, y- to the wire's x+, y-, x-, y+.

    Parameters
    ----------
    values : array_like, shape (4,)
        Values in the package's order.

    Returns
    -------
    ndarray, shape (4,)
        The same values in the wire order.
    """
    arr = np.asarray(values)
    if arr.shape != (4,):
        raise ProtocolError(f'need 4 values (one per coil), got shape {arr.shape}')
    return arr[_TO_WIRE]


def from_wire(values: ArrayLike) -> NDArray:
    """Reorder four per-coil values from the wire's x+, y-, x-, y+ to x+, x-, y+, y-.

    Parameters
    ----------
    values : array_like, shape (4,)
        Values in the wire order.

    Returns
    -------
    ndarray, shape (4,)
        The same values in the package's order.
    """
    arr = np.asarray(values)
    if arr.shape != (4,):
        raise ProtocolError(f'need 4 values (one per coil), got shape {arr.shape}')
    return arr[_FROM_WIRE]


def request(code: int) -> bytes:
    """Frame of a request without arguments (01, 02, 04, 05 or AA).

    Parameters
    ----------
    code : int
        The request byte.

    Returns
    -------
    bytes
        The COBS frame with its delimiter, e.g. ``02 01 00`` for ``01``.
    """
    if code not in (READ_SENSORS, READ_CURRENTS, RESET, STATUS, PING):
        raise ProtocolError(f'request {code:#04x} takes arguments or does not exist')
    return encode_frame(bytes([code]))


def pair_magnitudes(p_x: int, p_y: int) -> tuple[int, int, int, int]:
    """Return the four uint8 magnitudes (wire order x+, y-, x-, y+) of two pair differences.

    Parameters
    ----------
    p_x, p_y : int
        PWM applied to x+ (x- gets ``-p_x``) and to y+ (y- gets ``-p_y``),
        -255 .. 255.

    Returns
    -------
    tuple of 4 int
        ``(a, b, c, d) = (max(0, p_x), max(0, -p_y), max(0, -p_x), max(0, p_y))``.

    Raises
    ------
    ProtocolError
        If a difference is not an integer in -255 .. 255.
    """
    for name, p in (('p_x', p_x), ('p_y', p_y)):
        if isinstance(p, bool) or not isinstance(p, (int, np.integer)):
            raise ProtocolError(f'{name} must be an integer PWM count, got {p!r}')
        if not -PWM_MAX <= p <= PWM_MAX:
            raise ProtocolError(f'{name} must be within -{PWM_MAX}..{PWM_MAX}, got {p}')
    p_x, p_y = int(p_x), int(p_y)
    return max(0, p_x), max(0, -p_y), max(0, -p_x), max(0, p_y)


def set_pwm_request(p_x: int, p_y: int) -> bytes:
    """Frame of the ``03`` request that applies two pair differences.

    Parameters
    ----------
    p_x, p_y : int
        PWM of x+ and of y+ (-255 .. 255); x- and y- get the opposite.

    Returns
    -------
    bytes
        The COBS frame with its delimiter.
    """
    return encode_frame(bytes([SET_PWM, *pair_magnitudes(p_x, p_y)]))


def applied_pwm(a: int, b: int, c: int, d: int) -> NDArray[np.int64]:
    """PWM of each coil, order x+, x-, y+, y-, as the firmware applies ``03 a b c d``.

    Parameters
    ----------
    a, b, c, d : int
        The uint8 magnitudes, wire order x+, y-, x-, y+.

    Returns
    -------
    ndarray of int64, shape (4,)
        ``(p_x, -p_x, p_y, -p_y)`` with ``p_x = a - c``, ``p_y = d - b``.
    """
    p_x, p_y = int(a) - int(c), int(d) - int(b)
    return np.array([p_x, -p_x, p_y, -p_y], dtype=np.int64)


@dataclass(frozen=True)
class SensorsReply:
    """Reply to ``01``: the latest processed field and its filtered derivative.

    Attributes
    ----------
    field_mT : tuple of 3 float
        Bx, By, Bz in mT (baseline and feedthrough removed; x, y low-pass filtered).
    rate_mT_s : tuple of 3 float
        dBx, dBy, dBz in mT/s (dBz is always 0).
    """

    field_mT: tuple[float, float, float]  # noqa: N815 (unit symbol mT)
    rate_mT_s: tuple[float, float, float]  # noqa: N815 (unit symbol mT)


@dataclass(frozen=True)
class CurrentsReply:
    """Reply to ``02``: the coil currents, A, order x+, x-, y+, y- (converted from the wire)."""

    currents_A: tuple[float, float, float, float]  # noqa: N815 (unit symbol A)


@dataclass(frozen=True)
class AckReply:
    """Reply to ``03`` or ``04``: the request byte."""

    code: int


@dataclass(frozen=True)
class StatusReply:
    """Reply to ``05``: the constant bytes (4 solenoids, 9) and the uptime in s."""

    solenoids: int
    sensors: int
    uptime_s: int


@dataclass(frozen=True)
class ErrorReply:
    """The error reply ``00 code`` (103: unknown request)."""

    code: int


Reply = SensorsReply | CurrentsReply | AckReply | StatusReply | ErrorReply


def sensors_payload(field_mT: ArrayLike, rate_mT_s: ArrayLike) -> bytes:  # noqa: N803
    """Payload of the ``01`` reply (25 bytes).

    Parameters
    ----------
    field_mT : array_like, shape (3,)
        Bx, By, Bz in mT.
    rate_mT_s : array_like, shape (3,)
        dBx, dBy, dBz in mT/s.
    """
    values = np.concatenate([np.ravel(field_mT), np.ravel(rate_mT_s)]).astype('<f4')
    if values.shape != (6,):
        raise ProtocolError(f'need 3 field and 3 rate values, got {values.size} in all')
    return bytes([READ_SENSORS]) + values.tobytes()


def currents_payload(currents_A: ArrayLike) -> bytes:  # noqa: N803
    """Payload of the ``02`` reply (17 bytes), from currents in the order x+, x-, y+, y-.

    Parameters
    ----------
    currents_A : array_like, shape (4,)
        Coil currents in A, package order (written in the wire order).
    """
    return bytes([READ_CURRENTS]) + to_wire(np.asarray(currents_A, dtype='<f4')).tobytes()


def status_payload(uptime_s: int) -> bytes:
    """Payload of the ``05`` reply: ``05 04 09`` and the uptime as uint16 (wraps).

    Parameters
    ----------
    uptime_s : int
        Seconds since power-up (``millis() / 1000``, kept modulo 2**16).
    """
    return struct.pack('<BBBH', STATUS, STATUS_SOLENOIDS, STATUS_SENSORS, int(uptime_s) & 0xFFFF)


def error_payload(code: int = ERROR_UNKNOWN_REQUEST) -> bytes:
    """Payload of the error reply: ``00 code``.

    Parameters
    ----------
    code : int, optional
        Error code (103: unknown request).

    Returns
    -------
    bytes
        The payload before COBS encoding.
    """
    return bytes([ERROR, code])


def decode_reply(payload: bytes, request_code: int) -> Reply:
    """Decode a reply payload (after COBS) to the request it answers.

    Parameters
    ----------
    payload : bytes
        The decoded frame.
    request_code : int
        The request it answers (01 .. 05).

    Returns
    -------
    Reply
        The typed reply; an ``ErrorReply`` for ``00 code``.

    Raises
    ------
    ProtocolError
        If the reply is for another request or has the wrong length.
    """
    if len(payload) == 2 and payload[0] == ERROR:
        return ErrorReply(payload[1])
    expected = _REPLY_SIZE.get(request_code)
    if expected is None:
        raise ProtocolError(f'no framed reply exists for request {request_code:#04x}')
    if not payload or payload[0] != request_code or len(payload) != expected:
        raise ProtocolError(
            f'reply {payload.hex(" ")} does not answer request {request_code:#04x} '
            f'(expected {expected} bytes starting {request_code:02x})'
        )
    if request_code == READ_SENSORS:
        values = struct.unpack('<6f', payload[1:])
        return SensorsReply(values[:3], values[3:])
    if request_code == READ_CURRENTS:
        wire = np.frombuffer(payload, '<f4', count=4, offset=1)
        return CurrentsReply(tuple(float(v) for v in from_wire(wire)))
    if request_code == STATUS:
        solenoids, sensors, uptime = struct.unpack('<BBH', payload[1:])
        return StatusReply(solenoids, sensors, uptime)
    return AckReply(request_code)
