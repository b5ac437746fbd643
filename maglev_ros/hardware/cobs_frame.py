"""COBS frames on a byte stream: encode, decode, and split a stream into frames.

A frame is the COBS encoding (Consistent Overhead Byte Stuffing) of a
payload followed by one ``0x00`` delimiter; the encoding itself holds no
zero byte, so a receiver finds frame ends without knowing lengths. The
encoding is the ``cobs`` package's (a C extension), which produces the same
bytes as the V4x PC-control firmware's encoder for every payload shorter than
254 bytes (all of its messages are).

``FrameSplitter`` cuts a byte stream at the delimiters and decodes each
frame; a frame that is not valid COBS, or longer than ``max_frame`` bytes,
is dropped and counted, and the splitter carries on at the next delimiter
(resynchronisation after garbage or a half frame costs at most the frame it
damaged).
"""

from __future__ import annotations

from dataclasses import dataclass

from cobs import cobs

__all__ = [
    'DELIMITER',
    'FrameError',
    'FrameSplitter',
    'FrameStats',
    'decode_frame',
    'encode_frame',
]

DELIMITER = b'\x00'


class FrameError(ValueError):
    """Bytes that are not one valid COBS frame."""


def encode_frame(payload: bytes) -> bytes:
    """Encode a payload as one frame: COBS bytes, then the ``0x00`` delimiter.

    Parameters
    ----------
    payload : bytes
        Any bytes (zeros allowed).

    Returns
    -------
    bytes
        ``len(payload) + 2`` bytes for payloads shorter than 254 bytes.
    """
    return cobs.encode(bytes(payload)) + DELIMITER


def decode_frame(frame: bytes) -> bytes:
    """Decode one frame (with or without its trailing delimiter).

    Parameters
    ----------
    frame : bytes
        COBS bytes, optionally followed by one ``0x00``.

    Returns
    -------
    bytes
        The payload.

    Raises
    ------
    FrameError
        If the bytes hold a zero before the end, are empty, or are not valid
        COBS (a code byte pointing past the end).
    """
    body = bytes(frame)
    if body.endswith(DELIMITER):
        body = body[:-1]
    if not body:
        raise FrameError('empty frame')
    if DELIMITER in body:
        raise FrameError(f'zero byte inside a COBS frame: {body.hex(" ")}')
    try:
        return cobs.decode(body)
    except cobs.DecodeError as err:
        raise FrameError(f'invalid COBS frame {body.hex(" ")}: {err}') from None


@dataclass(frozen=True)
class FrameStats:
    """Counters of a ``FrameSplitter``.

    Attributes
    ----------
    frames : int
        Valid frames decoded.
    bad_frames : int
        Delimited frames dropped (invalid COBS, too long, or empty).
    dropped_bytes : int
        Bytes dropped with them (delimiters not counted).
    """

    frames: int
    bad_frames: int
    dropped_bytes: int


class FrameSplitter:
    """Cut a byte stream into COBS frames and decode them.

    Parameters
    ----------
    max_frame : int, optional
        Longest frame body accepted, bytes (without the delimiter); the
        bytes of a longer frame are dropped up to its delimiter.
    """

    def __init__(self, max_frame: int = 254) -> None:
        if max_frame < 1:
            raise ValueError(f'max_frame must be >= 1, got {max_frame}')
        self.max_frame = int(max_frame)
        self._buf = bytearray()
        self._overlong = False  # the current frame exceeded max_frame: drop to the delimiter
        self._frames = 0
        self._bad = 0
        self._dropped = 0

    @property
    def stats(self) -> FrameStats:
        """Snapshot of the counters."""
        return FrameStats(self._frames, self._bad, self._dropped)

    @property
    def pending(self) -> bytes:
        """Bytes of the frame not yet delimited."""
        return bytes(self._buf)

    def clear(self) -> int:
        """Drop the undelimited bytes (counted as dropped); return how many."""
        n = len(self._buf)
        self._dropped += n
        self._buf.clear()
        self._overlong = False
        return n

    def feed(self, data: bytes) -> list[bytes]:
        """Take stream bytes; return the payloads of the frames they complete.

        Parameters
        ----------
        data : bytes
            Bytes as read from the port, any length.

        Returns
        -------
        list of bytes
            Decoded payloads, in order (bad frames are skipped and counted).
        """
        out: list[bytes] = []
        start = 0
        while True:
            end = data.find(DELIMITER, start)
            if end < 0:
                self._take(data[start:])
                return out
            self._take(data[start:end])
            body, overlong = bytes(self._buf), self._overlong
            self._buf.clear()
            self._overlong = False
            start = end + 1
            if overlong or not body:
                if overlong:
                    self._bad += 1
                continue  # a lone delimiter is no frame (and no error)
            try:
                out.append(cobs.decode(body))
            except cobs.DecodeError:
                self._bad += 1
                self._dropped += len(body)
                continue
            self._frames += 1

    def _take(self, chunk: bytes) -> None:
        if self._overlong:
            self._dropped += len(chunk)
            return
        self._buf += chunk
        if len(self._buf) > self.max_frame:
            self._dropped += len(self._buf)
            self._buf.clear()
            self._overlong = True
