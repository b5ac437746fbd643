import numpy as np
import pytest

from maglev_ros.hardware.packet import (
    PACKET_END,
    PWM_FULL_SCALE,
    CommandParser,
    PacketError,
    decode_command,
    encode_command,
    is_sendable,
    sendable_pwm,
)

ALL_PWM = np.arange(-PWM_FULL_SCALE, PWM_FULL_SCALE + 1)


def test_unsendable_values_are_exactly_low_byte_0x3e():
    ok = is_sendable(ALL_PWM)
    unsendable = ALL_PWM[~ok]
    assert np.all(unsendable % 256 == 0x3E)
    assert np.all(ALL_PWM[ok] % 256 != 0x3E)
    assert len(unsendable) == 32
    assert 62 in unsendable and -194 in unsendable and 3902 in unsendable and -4034 in unsendable


def test_nearest_sendable_rule_and_worst_case_error():
    sent = sendable_pwm(ALL_PWM).astype(int)
    err = sent - ALL_PWM
    assert np.abs(err).max() == 1
    assert np.all(is_sendable(sent))
    moved = err != 0
    np.testing.assert_array_equal(moved, ~is_sendable(ALL_PWM))
    # towards zero, never past it, and never out of range
    assert np.all(np.abs(sent[moved]) == np.abs(ALL_PWM[moved]) - 1)
    assert np.abs(sent).max() <= PWM_FULL_SCALE


@pytest.mark.parametrize('slot', range(4))
def test_every_value_in_every_slot_passes_the_board_parser(slot):
    rng = np.random.default_rng(slot)
    commands = rng.integers(-PWM_FULL_SCALE, PWM_FULL_SCALE + 1, size=(ALL_PWM.size, 4))
    commands[:, slot] = ALL_PWM
    stream = b''.join(encode_command(row) for row in commands)
    parser = CommandParser()
    accepted = np.array(parser.feed(stream))
    assert accepted.shape == commands.shape
    assert parser.discarded == 0
    np.testing.assert_array_equal(accepted, sendable_pwm(commands))
    assert np.abs(accepted - commands).max() <= 1


def test_packet_layout():
    packet = encode_command([1, -1, 4096, -4096])
    assert packet == b'<' + np.array([1, -1, 4096, -4096], '<i2').tobytes() + b'>'
    assert len(packet) == 10
    assert PACKET_END not in packet[:-1]
    assert decode_command(packet[1:-1]) == (1, -1, 4096, -4096)


def test_payload_may_contain_start_byte():
    # 0x3C = '<' as a low byte is stored like any payload byte
    packet = encode_command([60, 60, 0, 0])
    assert packet.count(b'<') == 3
    assert CommandParser().feed(packet) == [(60, 60, 0, 0)]


@pytest.mark.parametrize(
    'counts, match',
    [
        ([0, 0, 0], r'counts must have shape \(4,\), got shape \(3,\)'),
        ([0, 0, 0, 4097], r'within -4096..4096 counts, got \[0, 0, 0, 4097\]'),
        ([0, 0, 0, -5000], 'within -4096..4096'),
        ([0.0, np.nan, 0.0, 0.0], 'counts must be finite'),
        ([0.0, 1.5, 0.0, 0.0], 'whole PWM counts'),
        (['a', 'b', 'c', 'd'], 'integer PWM counts'),
    ],
)
def test_encode_rejects_bad_input(counts, match):
    with pytest.raises(PacketError, match=match):
        encode_command(counts)


def test_encode_accepts_whole_floats():
    assert encode_command([1.0, -2.0, 0.0, 62.0]) == encode_command([1, -2, 0, 61])


def test_parser_ignores_bytes_until_start():
    parser = CommandParser()
    assert parser.feed(b'\x00\xff>>abc' + encode_command([5, 6, 7, 8])) == [(5, 6, 7, 8)]
    assert parser.discarded == 0


def test_parser_discards_short_packet():
    parser = CommandParser()
    assert parser.feed(b'<1234567>') == []
    assert parser.discarded == 1
    assert not parser.receiving


def test_parser_resets_after_nine_bytes_and_consumes_the_ninth():
    parser = CommandParser()
    # nine payload bytes, the ninth being '<': the parser resets and waits
    # for the next '<', so the following 8 bytes and '>' are ignored
    assert parser.feed(b'<12345678<abcdefgh>') == []
    assert parser.discarded == 1
    assert parser.feed(encode_command([1, 2, 3, 4])) == [(1, 2, 3, 4)]


def test_parser_out_of_sync_loses_at_most_one_packet():
    rng = np.random.default_rng(7)
    commands = rng.integers(-4096, 4097, size=(50, 4))
    stream = b''.join(encode_command(c) for c in commands)
    for cut in range(1, 10):
        # start in the middle of a packet (the parser has seen '<' earlier)
        parser = CommandParser()
        parser.feed(b'<')
        accepted = parser.feed(stream[cut:])
        assert len(accepted) >= len(commands) - 2
        np.testing.assert_array_equal(accepted, sendable_pwm(commands[-len(accepted) :]))


def test_parser_byte_by_byte_equals_bulk():
    stream = b''.join(encode_command([v, -v, 2 * v, 0]) for v in range(0, 2000, 37))
    bulk = CommandParser().feed(stream)
    parser = CommandParser()
    single = [p for byte in stream for p in parser.feed(bytes([byte]))]
    assert single == bulk and len(bulk) == len(range(0, 2000, 37))


def test_decode_command_checks_length():
    with pytest.raises(PacketError, match='payload must be 8 bytes, got 7'):
        decode_command(b'1234567')
