"""COBS frames: hand-computed encodings, the firmware's encoder, stream splitting."""

import random

import pytest

from maglev_ros.hardware.cobs_frame import FrameError, FrameSplitter, decode_frame, encode_frame


def firmware_encode(payload: bytes) -> bytes:
    """The V4x firmware's encoder, transcribed from its algorithm, plus the delimiter."""
    out = bytearray([0])
    code_at, code = 0, 1
    for byte in payload:
        if byte == 0:
            out[code_at] = code
            code_at, code = len(out), 1
            out.append(0)
        else:
            out.append(byte)
            code += 1
            if code == 0xFF:
                out[code_at] = code
                code_at, code = len(out), 1
                out.append(0)
    out[code_at] = code
    return bytes(out) + b'\x00'


@pytest.mark.parametrize(
    ('payload', 'wire'),
    [
        (b'\x01', '02 01 00'),
        (b'\xaa', '02 aa 00'),
        (b'\x00\x67', '01 02 67 00'),
        (b'\x03\x0a\x00\x00\x00', '03 03 0a 01 01 01 00'),
        (b'\x05\x04\x09\x00\x01', '04 05 04 09 02 01 00'),
        (b'\x00', '01 01 00'),
    ],
)
def test_hand_computed_frames(payload, wire):
    assert encode_frame(payload).hex(' ') == wire
    assert decode_frame(bytes.fromhex(wire)) == payload


def test_matches_the_firmware_encoder_for_every_message_size():
    rng = random.Random(1)
    for size in range(1, 64):
        for _ in range(50):
            payload = bytes(
                rng.choice([0, 0, 1, 0x7F, 0xFF, rng.randrange(256)]) for _ in range(size)
            )
            assert encode_frame(payload) == firmware_encode(payload)
            assert decode_frame(encode_frame(payload)) == payload


@pytest.mark.parametrize(
    ('frame', 'match'),
    [
        (b'', 'empty'),
        (b'\x00', 'empty'),
        (b'\x02\x00\x01\x00', 'zero byte'),
        (b'\x05\x01', 'invalid'),
    ],
)
def test_decode_rejects_bad_frames(frame, match):
    with pytest.raises(FrameError, match=match):
        decode_frame(frame)


def test_splitter_across_chunks_and_garbage():
    frames = [encode_frame(bytes([1, 2, 0, 3])), encode_frame(b'\x00\x67'), encode_frame(b'\x04')]
    stream = b'\x07\x01' + b'\x00' + b''.join(frames)  # a bad frame (07 01), then three good
    splitter = FrameSplitter()
    got = []
    for i in range(len(stream)):  # one byte at a time
        got += splitter.feed(stream[i : i + 1])
    assert got == [bytes([1, 2, 0, 3]), b'\x00\x67', b'\x04']
    assert splitter.stats.frames == 3
    assert splitter.stats.bad_frames == 1
    assert splitter.stats.dropped_bytes == 2


def test_splitter_drops_overlong_frames_and_resumes():
    splitter = FrameSplitter(max_frame=30)
    got = splitter.feed(bytes(range(1, 100)) + b'\x00' + encode_frame(b'\x03'))
    assert got == [b'\x03']
    assert splitter.stats.bad_frames == 1
    assert splitter.stats.dropped_bytes == 99
    assert splitter.feed(b'\x01\x02') == []
    assert splitter.pending == b'\x01\x02'
    assert splitter.clear() == 2
