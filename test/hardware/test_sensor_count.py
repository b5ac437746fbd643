from functools import partial

import numpy as np
import pytest

from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.sensor_count import (
    SensorCountError,
    detect_sensor_count,
    probe_sensor_count,
)
from maglev_ros.hardware.v2x_stream import pack_records
from maglev_ros.hardware.virtual_board import VirtualBoard


def stream(n_sensors, n_records=200, seed=0):
    rng = np.random.default_rng(seed)
    stamps = 1_000_000 + 200 * np.arange(n_records)
    fields = rng.normal(0.0, 30.0, (n_records, n_sensors, 3))
    pwm = rng.integers(-300, 300, (n_records, 4))
    return pack_records(stamps, fields, pwm)


@pytest.mark.parametrize('n_sensors', [1, 2, 3, 5])
@pytest.mark.parametrize('cut', [0, 7, 30])
def test_the_count_of_a_stream_starting_anywhere(n_sensors, cut):
    assert detect_sensor_count(stream(n_sensors)[cut:]) == n_sensors


def test_a_one_sensor_stream_is_not_taken_for_two_records_of_three():
    # two 24-byte records read as one of 48 bytes also step regularly (by 400 us)
    data = np.zeros(200, dtype=[('t', '<u4'), ('f', '<f4', (3,)), ('p', '<i2', (4,))])
    data['t'] = 200 * np.arange(200)
    assert detect_sensor_count(data.tobytes()) == 1


def test_too_few_bytes_or_noise_tell_nothing():
    assert detect_sensor_count(stream(3)[:200]) is None
    assert detect_sensor_count(np.random.default_rng(1).bytes(20000)) is None


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_the_probe_reads_a_virtual_board(n_sensors):
    factory = partial(V2xFirmware, LinearPlant.default(n_sensors), n_sensors, startup_delay=0.1)
    with VirtualBoard(factory) as board:
        assert probe_sensor_count(board.path, timeout=10.0) == n_sensors


def test_a_silent_port_is_an_error_at_the_timeout():
    factory = partial(V2xFirmware, LinearPlant.default(1), 1, startup_delay=30.0)
    with VirtualBoard(factory) as board:
        with pytest.raises(SensorCountError, match='nothing in 0.5 s'):
            probe_sensor_count(board.path, timeout=0.5)


def test_a_missing_port_is_an_error():
    with pytest.raises(SensorCountError, match='cannot open /nonexistent/tty'):
        probe_sensor_count('/nonexistent/tty', timeout=0.5)
