"""The V4x PC-control emulator, without a pty: set-up, filters, freeze, framing, errors."""

import numpy as np
import pytest

from maglev_ros.hardware import v4x_pc_protocol as p
from maglev_ros.hardware.cobs_frame import FrameSplitter, decode_frame, encode_frame
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.v4x_pc_firmware import (
    FREEZE_LIMIT,
    FREEZE_RESET_US,
    V4xPcFirmware,
    adc_current,
)

SCALING = CurrentScaling.from_supply(12.0, 4.0, full_scale=255)  # 85 counts per A
# field per PWM count of each coil (x+, x-, y+, y-) on Bx, By, Bz, mT
GAIN = np.array([[0.02, -0.01, 0.001, 0.0], [0.0, 0.002, 0.03, -0.015], [0.05, 0.05, 0.05, 0.05]])
OFFSET = np.array([0.5, -0.3, 40.0])


class Plant:
    """Linear in the PWM, plus a magnet field switched on by the test, plus noise."""

    def __init__(self, noise=0.01, seed=0):
        self.rng = np.random.default_rng(seed)
        self.noise = noise
        self.magnet = np.zeros(3)
        self.calls = 0

    def __call__(self, pwm, t):
        self.calls += 1
        field = OFFSET + self.magnet + GAIN @ np.asarray(pwm, float)
        return (field + self.rng.normal(0.0, self.noise, 3))[None, :]


def booted(plant=None, **kwargs):
    plant = plant or Plant()
    fw = V4xPcFirmware(plant, scaling=SCALING, **kwargs)
    assert fw.advance_to(fw.setup_us) == b''
    return fw, plant


def ask(fw, frame, after_us=200):
    fw.receive(frame)
    return fw.advance_to(fw.now_us + after_us)


def test_setup_baseline_and_feedthrough_slopes():
    fw, plant = booted()
    np.testing.assert_allclose(fw.baseline_mT, OFFSET, atol=0.002)  # 1000 noisy reads
    # slope = field per A on the coil's axis (negated for x+ and y+): gain * 85 counts/A,
    # up to the ADC's 6.45 mA step
    expected = [-GAIN[0, 0] * 85, GAIN[0, 1] * 85, -GAIN[1, 2] * 85, GAIN[1, 3] * 85]
    np.testing.assert_allclose(fw.slopes, expected, rtol=0.01)
    assert fw.pwm.tolist() == [0, 0, 0, 0]
    assert 3.7e6 <= fw.setup_us <= 4.4e6
    assert plant.calls == fw.setup_us // 200 + 1  # the plant steps every 200 us throughout


def test_requests_during_setup_are_answered_when_it_ends():
    fw = V4xPcFirmware(Plant(), scaling=SCALING)
    fw.receive(p.request(p.STATUS))
    assert fw.advance_to(fw.setup_us - 200) == b''
    out = fw.advance_to(fw.setup_us)
    assert p.decode_reply(decode_frame(out), p.STATUS) == p.StatusReply(4, 9, 3)


def test_setup_plant_gives_the_baseline():
    setup = Plant(noise=0.0)
    fw = V4xPcFirmware(Plant(), scaling=SCALING, setup_plant=setup)
    main = fw.plant
    fw.advance_to(fw.setup_us - 200)
    assert main.calls == 0 and setup.calls > 0  # the magnet goes in after set-up
    fw.advance_to(fw.setup_us)
    assert main.calls == 1
    # meanMagField += reading / 1000.0, 1000 times, in float32 as the board does
    mean = np.zeros(3, dtype=np.float32)
    for _ in range(1000):
        mean = np.float32(mean + np.float32(OFFSET).astype(float) / 1000.0)
    np.testing.assert_array_equal(fw.baseline_mT, mean)
    np.testing.assert_allclose(fw.baseline_mT, OFFSET, rtol=2e-5)


def test_filters_and_feedthrough_removal():
    fw, plant = booted(Plant(noise=0.0), freeze_limit=10**9)
    plant.magnet = np.array([1.0, -2.0, 3.0])
    ask(fw, p.set_pwm_request(120, -60))
    fw.advance_to(fw.now_us + 200_000)  # 1000 samples: the filters settled
    field = p.decode_reply(decode_frame(ask(fw, p.request(p.READ_SENSORS))), 1).field_mT
    # x, y: magnet + coil field - each axis's own pair's feedthrough (exact up to the
    # ADC's resolution): the cross terms (y coils on x, x coils on y) stay; z unfiltered
    pwm = np.array([120, -120, -60, 60])
    cross = [GAIN[0, 2:] @ pwm[2:], GAIN[1, :2] @ pwm[:2]]
    np.testing.assert_allclose(field[:2], np.array([1.0, -2.0]) + cross, atol=0.02)
    z = np.float32(np.float32(OFFSET[2] + 3.0 + GAIN[2] @ pwm) - fw.baseline_mT[2])
    assert field[2] == z
    # one step of the first-order filter, float32 as the board computes it
    before = fw.field_mT.copy()
    plant.magnet = np.array([2.0, -2.0, 3.0])
    fw.advance_to(fw.now_us + 200)
    raw_x = np.float32(fw.field_mT[0])
    x_in = (raw_x - 0.8 * before[0]) / 0.2  # the filter's input
    assert x_in == pytest.approx(2.0 + cross[0], abs=0.02)
    reply = p.decode_reply(decode_frame(ask(fw, p.request(p.READ_SENSORS), 0)), 1)
    assert reply.rate_mT_s[2] == 0.0 and reply.rate_mT_s[0] > 0  # dBz never computed


def test_currents_reply_is_the_adc_reading_in_our_order():
    fw, _ = booted()
    ask(fw, p.set_pwm_request(85, -170))
    reply = p.decode_reply(decode_frame(ask(fw, p.request(p.READ_CURRENTS))), 2)
    expected = adc_current(np.array([1.0, -1.0, -2.0, 2.0]))
    assert reply.currents_A == tuple(float(v) for v in expected)
    assert reply.currents_A[0] == pytest.approx(1.0, abs=0.004)


def test_freeze_reset_after_20_identical_readings():
    fw, plant = booted(Plant(noise=0.0))
    samples = fw.samples
    fw.advance_to(fw.now_us + 200 * (FREEZE_LIMIT + 1))
    assert fw.freeze_resets == 1
    stalled_at = fw.samples
    out = ask(fw, p.request(p.STATUS), FREEZE_RESET_US - 10_000)  # no reply during the reset
    assert out == b'' and fw.samples == stalled_at
    out = fw.advance_to(fw.now_us + 20_000)
    assert p.decode_reply(decode_frame(out), p.STATUS).solenoids == 4
    assert fw.samples > stalled_at > samples


def test_half_frame_stalls_one_second_after_the_last_byte_then_runs():
    fw, _ = booted()
    samples = fw.samples
    assert ask(fw, b'\x02\x01', 500_000) == b''  # '01' without its delimiter
    stalled = fw.samples
    assert stalled - samples <= 2
    assert ask(fw, b'', 499_000) == b''
    out = fw.advance_to(fw.now_us + 2_000)
    assert p.decode_reply(decode_frame(out), 1)  # decoded and answered after 1 s
    assert fw.half_frames == 1
    fw.advance_to(fw.now_us + 2_000)
    assert fw.samples > stalled


def test_half_frame_merges_with_the_next_request():
    fw, _ = booted()
    fw.receive(b'\x03\x05\x10')  # a 03 frame cut short
    out = ask(fw, p.request(p.READ_SENSORS))
    # 03 05 10 02 01 decodes to 05 10 00 01 00: the board answers a status request
    assert decode_frame(out)[0] == p.STATUS


def test_64_byte_buffer_splits_long_frames():
    fw, _ = booted()
    out = ask(fw, bytes([0x40] + [0x11] * 62) + p.request(p.READ_SENSORS))  # no 0 in 63 bytes
    assert fw.split_frames == 1
    frames = FrameSplitter().feed(out)
    assert frames[0] == p.error_payload()  # 0x11 is no request
    assert frames[1][0] == p.READ_SENSORS


def test_error_reply_lone_zero_and_ping():
    fw, _ = booted()
    assert ask(fw, encode_frame(b'\x42')) == bytes.fromhex('01 02 67 00')
    assert ask(fw, b'\x00') == b''  # a lone delimiter: no reply
    assert ask(fw, p.request(p.PING)) == b'\xee'
    assert fw.errors_sent == 1


def test_no_watchdog():
    fw, _ = booted()
    ask(fw, p.set_pwm_request(-200, 30))
    fw.advance_to(fw.now_us + 3_000_000)
    assert fw.pwm.tolist() == [-200, 200, 30, -30]
    ask(fw, p.request(p.RESET))
    assert fw.pwm.tolist() == [0, 0, 0, 0]


def test_every_pair_difference_is_applied():
    fw, _ = booted()
    for p_x in range(-255, 256):
        assert ask(fw, p.set_pwm_request(p_x, -p_x), 0) == b'\x02\x03\x00'
        assert fw.pwm.tolist() == [p_x, -p_x, -p_x, p_x]


def test_one_megabyte_of_random_bytes_never_breaks_the_board():
    fw, _ = booted()
    rng = np.random.default_rng(5)
    garbage = rng.integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
    out = bytearray()
    for k in range(0, len(garbage), 4096):
        out += ask(fw, garbage[k : k + 4096], 1000)
    out += ask(fw, b'\x00' + p.request(p.READ_SENSORS), 1_100_000)  # end a half frame
    executed = sum(v for c, v in fw.requests.items() if c != 0x100)
    assert executed > 1000
    assert fw.errors_sent > 0 and fw.split_frames > 0
    assert np.all(np.isfinite(fw.field_mT))
    assert -255 <= fw.pwm[0] <= 255 and fw.pwm[1] == -fw.pwm[0]
    frames = FrameSplitter().feed(bytes(out).replace(b'\xee', b''))
    assert frames[-1][0] == p.READ_SENSORS
