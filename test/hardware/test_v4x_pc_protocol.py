"""V4x PC-control messages, from the protocol table: byte-exact round trips."""

import struct

import numpy as np
import pytest

from maglev_ros.hardware import v4x_pc_protocol as p
from maglev_ros.hardware.cobs_frame import decode_frame, encode_frame


@pytest.mark.parametrize(
    ('code', 'wire'),
    [
        (p.READ_SENSORS, '02 01 00'),
        (p.READ_CURRENTS, '02 02 00'),
        (p.RESET, '02 04 00'),
        (p.STATUS, '02 05 00'),
        (p.PING, '02 aa 00'),
    ],
)
def test_requests_without_arguments(code, wire):
    assert p.request(code).hex(' ') == wire
    assert decode_frame(bytes.fromhex(wire)) == bytes([code])


def test_request_with_arguments_is_refused_without_them():
    with pytest.raises(p.ProtocolError, match='takes arguments'):
        p.request(p.SET_PWM)


@pytest.mark.parametrize(
    ('p_x', 'p_y', 'payload'),
    [
        (0, 0, '03 00 00 00 00'),
        (10, 0, '03 0a 00 00 00'),
        (-10, 0, '03 00 00 0a 00'),
        (0, 20, '03 00 00 00 14'),
        (0, -20, '03 00 14 00 00'),
        (255, -255, '03 ff ff 00 00'),
        (-1, 1, '03 00 00 01 01'),
    ],
)
def test_set_pwm_payloads(p_x, p_y, payload):
    frame = p.set_pwm_request(p_x, p_y)
    assert decode_frame(frame).hex(' ') == payload
    a, b, c, d = bytes.fromhex(payload)[1:]
    assert p.applied_pwm(a, b, c, d).tolist() == [p_x, -p_x, p_y, -p_y]


def test_every_pair_difference_round_trips():
    for p_x in range(-255, 256):
        for p_y in (-255, -1, 0, 1, 255, p_x):
            payload = decode_frame(p.set_pwm_request(p_x, p_y))
            assert payload[0] == p.SET_PWM and len(payload) == 5
            assert p.applied_pwm(*payload[1:]).tolist() == [p_x, -p_x, p_y, -p_y]


@pytest.mark.parametrize(
    ('p_x', 'p_y', 'match'), [(256, 0, 'p_x'), (0, -256, 'p_y'), (1.5, 0, 'integer')]
)
def test_set_pwm_refuses_out_of_range(p_x, p_y, match):
    with pytest.raises(p.ProtocolError, match=match):
        p.set_pwm_request(p_x, p_y)


def test_wire_order():
    ours = np.array([1.0, 2.0, 3.0, 4.0])  # x+, x-, y+, y-
    assert p.to_wire(ours).tolist() == [1.0, 4.0, 2.0, 3.0]  # x+, y-, x-, y+
    assert p.from_wire(p.to_wire(ours)).tolist() == ours.tolist()


def test_sensors_reply_round_trip():
    field, rate = (1.0, -2.5, 0.0), (100.0, -0.25, 0.0)
    payload = p.sensors_payload(field, rate)
    assert payload == bytes([1]) + struct.pack('<6f', *field, *rate)
    assert len(payload) == 25
    frame = encode_frame(payload)
    assert len(frame) == 27 and b'\x00' not in frame[:-1]
    reply = p.decode_reply(decode_frame(frame), p.READ_SENSORS)
    assert reply == p.SensorsReply(field, rate)


def test_currents_reply_is_in_wire_order_and_decodes_to_ours():
    ours = (0.5, -0.5, 1.25, -1.25)  # x+, x-, y+, y-
    payload = p.currents_payload(ours)
    assert payload == bytes([2]) + struct.pack('<4f', 0.5, -1.25, -0.5, 1.25)  # x+ y- x- y+
    reply = p.decode_reply(decode_frame(encode_frame(payload)), p.READ_CURRENTS)
    assert reply == p.CurrentsReply(ours)


@pytest.mark.parametrize('code', [p.SET_PWM, p.RESET])
def test_acks(code):
    frame = encode_frame(bytes([code]))
    assert frame == bytes([2, code, 0])
    assert p.decode_reply(decode_frame(frame), code) == p.AckReply(code)


def test_status_reply():
    payload = p.status_payload(300)
    assert payload.hex(' ') == '05 04 09 2c 01'
    assert encode_frame(payload).hex(' ') == '06 05 04 09 2c 01 00'
    assert p.decode_reply(payload, p.STATUS) == p.StatusReply(4, 9, 300)
    assert p.status_payload(65536 + 7)[3:] == b'\x07\x00'  # uint16 wraps


def test_error_reply():
    payload = p.error_payload()
    assert encode_frame(payload).hex(' ') == '01 02 67 00'
    for code in (p.READ_SENSORS, p.READ_CURRENTS, p.SET_PWM, p.RESET, p.STATUS):
        assert p.decode_reply(payload, code) == p.ErrorReply(103)


@pytest.mark.parametrize(
    ('payload', 'code', 'match'),
    [
        (b'\x01' + bytes(24), p.READ_CURRENTS, 'does not answer'),
        (b'\x01' + bytes(20), p.READ_SENSORS, 'expected 25 bytes'),
        (b'\x03', p.RESET, 'does not answer'),
        (b'\xee', p.PING, 'no framed reply'),
    ],
)
def test_mismatched_replies(payload, code, match):
    with pytest.raises(p.ProtocolError, match=match):
        p.decode_reply(payload, code)
