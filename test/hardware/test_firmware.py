import numpy as np
import pytest

from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware, V4xFirmware
from maglev_ros.hardware.packet import encode_command
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.v2x_stream import RecordDecoder, record_size
from maglev_ros.hardware.v4x_telemetry import InfoMessage, TelemetrySample, TelemetryStream

WRAP = 1 << 32


def decode(data, n_sensors=1):
    decoder = RecordDecoder(n_sensors, confirm=False)
    batch = decoder.feed(data)
    assert decoder.stats.dropped_bytes == 0
    return batch


def test_start_up_delay_then_bursts_of_five():
    board = V2xFirmware(LinearPlant.default(1), 1)
    assert board.advance_to(1_999_999) == b''
    assert not board.running
    # ticks at 2.0000 s, 2.0002 s, ...: the first burst is complete with the fifth tick
    assert board.advance_to(2_000_799) == b''
    burst = board.advance_to(2_000_800)
    assert len(burst) == 5 * record_size(1)
    assert board.running
    batch = decode(burst)
    np.testing.assert_array_equal(batch.time_us, 2_000_000 + 200 * np.arange(5))
    assert len(board.advance_to(3_000_800)) == 1000 * 5 * record_size(1)


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_records_carry_plant_fields_and_applied_pwm(n_sensors):
    plant = LinearPlant.default(n_sensors)
    board = V2xFirmware(plant, n_sensors, startup_delay=0.0)
    data = board.advance_to(1000)  # ticks 0 .. 1000
    board.receive(encode_command([100, -200, 62, 4096]))  # 62 is sent as 61
    batch = decode(data + board.advance_to(9800), n_sensors)
    assert len(batch) == 50
    applied = np.array([100, -200, 61, 4096])
    np.testing.assert_array_equal(batch.pwm[:6], 0)
    np.testing.assert_array_equal(batch.pwm[6:], np.tile(applied, (len(batch) - 6, 1)))
    np.testing.assert_array_equal(batch.field_mT[0], plant(np.zeros(4), 0.0).astype(np.float32))
    np.testing.assert_array_equal(batch.field_mT[-1], plant(applied, 0.0).astype(np.float32))
    assert board.accepted[-1] == (1200, (100, -200, 61, 4096))


def test_packet_is_parsed_at_the_next_tick_byte_by_byte():
    board = V2xFirmware(LinearPlant.default(1), 1, startup_delay=0.0)
    packet = encode_command([1, 2, 3, 4])
    for i, byte in enumerate(packet):
        board.receive(bytes([byte]))
        board.advance_to(200 * i)
    assert board.advance_to(200 * len(packet)) is not None
    assert list(board.pwm) == [1, 2, 3, 4]
    assert board.parser.accepted == 1


def test_watchdog_zeroes_once_after_one_second():
    board = V2xFirmware(LinearPlant.default(1), 1, startup_delay=0.0)
    board.receive(encode_command([500, 500, 500, 500]))
    board.advance_to(0)  # accepted at tick 0
    board.advance_to(1_000_000)
    assert list(board.pwm) == [500] * 4  # exactly 1 s: not yet "more than 1 s"
    board.advance_to(1_000_200)
    assert list(board.pwm) == [0] * 4
    assert board.watchdog_trips == 1
    board.advance_to(5_000_000)
    assert board.watchdog_trips == 1  # once, until the next accepted packet
    board.receive(encode_command([7, 7, 7, 7]))
    board.advance_to(5_000_200)
    assert list(board.pwm) == [7] * 4
    board.advance_to(6_000_400)
    assert list(board.pwm) == [0] * 4 and board.watchdog_trips == 2


def test_rejected_packets_do_not_feed_the_watchdog():
    board = V2xFirmware(LinearPlant.default(1), 1, startup_delay=0.0)
    board.receive(encode_command([9, 9, 9, 9]))
    board.advance_to(0)
    for t in range(100_000, 2_000_000, 100_000):
        board.receive(b'<' + bytes(9) + b'>')  # nine payload bytes: discarded
        board.advance_to(t)
    assert list(board.pwm) == [0] * 4
    assert board.parser.discarded == 19


def test_clock_wraps():
    board = V2xFirmware(
        LinearPlant.default(1), 1, clock_start_us=WRAP - 2_000_000 - 1000, startup_delay=2.0
    )
    data = board.advance_to(2_010_000)
    decoder = RecordDecoder(1, confirm=False)
    batch = decoder.feed(data)
    raw = batch.time_us % WRAP
    assert raw[0] == WRAP - 1000 and raw[-1] < 10_000
    assert np.all(np.diff(batch.time_us) == 200)
    assert decoder.stats.wraps == 1


def test_port_open_restarts_the_start_up_wait():
    board = V2xFirmware(LinearPlant.default(1), 1, startup_delay=0.5)
    assert len(board.advance_to(1_000_000)) > 0
    board.port_opened()
    assert board.advance_to(1_499_999) == b''
    batch = decode(board.advance_to(1_600_000))
    assert batch.time_us[0] == 1_500_000  # the clock kept counting since power-up


def test_tamper_next_burst():
    board = V2xFirmware(LinearPlant.default(1), 1, startup_delay=0.0)
    board.tamper_next_burst(lambda burst: burst[10:])
    data = board.advance_to(1800)
    assert len(data) == 10 * record_size(1) - 10


def test_plant_shape_is_checked():
    board = V2xFirmware(lambda pwm, t: np.zeros((2, 3)), 1, startup_delay=0.0)
    with pytest.raises(ValueError, match=r'plant must return shape \(1, 3\), got \(2, 3\)'):
        board.advance_to(0)


@pytest.mark.parametrize(
    'kwargs, error, match',
    [
        ({'plant': 3}, TypeError, 'plant must be callable, got int'),
        ({'n_sensors': 0}, ValueError, 'n_sensors must be an int >= 1, got 0'),
        ({'clock_start_us': WRAP}, ValueError, 'clock_start_us must be in'),
        ({'startup_delay': -1.0}, ValueError, 'startup_delay must be >= 0 s, got -1.0'),
    ],
)
def test_v2x_argument_errors(kwargs, error, match):
    args = {'plant': LinearPlant.default(1), 'n_sensors': 1} | kwargs
    with pytest.raises(error, match=match):
        V2xFirmware(args.pop('plant'), args.pop('n_sensors'), **args)


def test_linear_plant():
    plant = LinearPlant(np.zeros((1, 3)), np.ones((1, 3, 4)))
    np.testing.assert_array_equal(plant([1, 2, 3, 4], 0.0), [[10.0, 10.0, 10.0]])
    with pytest.raises(ValueError, match=r'gain_mT_per_count must have shape \(1, 3, 4\)'):
        LinearPlant(np.zeros((1, 3)), np.ones((1, 3)))


def test_v4x_messages_and_telemetry():
    scaling = CurrentScaling(1000.0)
    plant = LinearPlant.default(2)

    def current(t):
        return np.array([0.5, -0.5, 0.25, -0.25]) if t > 2.01 else np.zeros(4)

    board = V4xFirmware(plant, 2, current=current, scaling=scaling, log_period=0.001)
    assert board.advance_to(1_999_000) == b''
    stream = TelemetryStream(2)
    items = stream.feed(board.advance_to(2_005_000))
    texts = [i.text for i in items if isinstance(i, InfoMessage)]
    assert texts == [
        'Sensor on channel 0 initialized successfully.',
        'Sensor on channel 1 initialized successfully.',
        'Calibrating sensors...',
        'Sensor calibration complete.',
    ]
    samples = [i for i in items if isinstance(i, TelemetrySample)]
    assert len(samples) == 6 and samples[0].time == 2.0
    np.testing.assert_array_equal(samples[0].field_mT, 0.0)  # baseline removed
    board.inject_freeze()
    items = stream.feed(board.advance_to(2_020_000))
    assert items[0].text == 'Sensor freeze detected! Resetting...'
    assert items[1].text == 'I2C and sensor reset complete'
    last = items[-1]
    np.testing.assert_array_equal(last.current, [0.5, -0.5, 0.25, -0.25])
    counts = scaling.to_counts(last.current)
    np.testing.assert_allclose(last.field_mT, plant(counts, 0) - plant(np.zeros(4), 0), atol=1e-6)
    assert stream.stats.malformed == 0
