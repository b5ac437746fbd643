import numpy as np
import pytest

from maglev_ros.hardware.v4x_telemetry import (
    InfoMessage,
    Severity,
    TelemetryError,
    TelemetrySample,
    TelemetryStream,
    format_telemetry_line,
    parse_telemetry_line,
)

DOC_LINE = (
    'time:12.345678,Ix_plus:0.123456,Ix_minus:-0.123456,Iy_plus:0.000000,Iy_minus:0.000000,'
    'bx0:0.512000,by0:-0.030000,bz0:41.200000,bx1:1.000000,by1:2.000000,bz1:-3.500000\r\n'
)


def test_parses_the_documented_line():
    sample = parse_telemetry_line(DOC_LINE)
    assert sample.time == 12.345678
    np.testing.assert_array_equal(sample.current, [0.123456, -0.123456, 0.0, 0.0])
    np.testing.assert_array_equal(sample.field_mT, [[0.512, -0.03, 41.2], [1.0, 2.0, -3.5]])


def test_format_round_trips_with_six_decimals():
    field = np.array([[0.1234564, -5.0, 41.2], [7.0, 8.0, 9.0], [0.0, 0.0, 1e-7]])
    line = format_telemetry_line(3.5, [0.5, -0.5, 0.25, -0.25], field)
    assert line.endswith(b'\r\n') and b'bz2:0.000000' in line
    sample = parse_telemetry_line(line.decode())
    np.testing.assert_allclose(sample.field_mT, field, atol=5e-7)
    assert sample.time == 3.5


@pytest.mark.parametrize(
    'line, match',
    [
        (
            'time:1.0,Ix_plus:0,Ix_minus:0,Iy_plus:0,bx0:1,by0:2,bz0:3',
            'must have time, 4 currents',
        ),
        (
            'time:1.0,Ix_plus:0,Ix_minus:0,Iy_plus:0,Iy_minus:x,bx0:1,by0:2,bz0:3',
            'Iy_minus must be a number',
        ),
        (
            'time:1.0,Ix_plus:nan,Ix_minus:0,Iy_plus:0,Iy_minus:0,bx0:1,by0:2,bz0:3',
            'Ix_plus must be finite',
        ),
        ('time:1.0,Ix_minus:0,Ix_plus:0,Iy_plus:0,Iy_minus:0,bx0:1,by0:2,bz0:3', 'keys must be'),
        (
            'time:1.0,Ix_plus:0,Ix_minus:0,Iy_plus:0,Iy_minus:0,bx0:1,by0:2 bz0:3',
            'must be a number',
        ),
    ],
)
def test_rejects_malformed_lines(line, match):
    with pytest.raises(TelemetryError, match=match):
        parse_telemetry_line(line)


def test_sensor_count_is_checked():
    with pytest.raises(TelemetryError, match='line must have 3 sensors, got 2'):
        parse_telemetry_line(DOC_LINE, n_sensors=3)


def test_stream_with_interleaved_informational_lines():
    lines = [
        b'Sensor on channel 7 initialized successfully.\r\n',
        b'Calibrating sensors...\r\n',
        b'Sensor calibration complete.\r\n',
        DOC_LINE.encode(),
        b'Sensor freeze detected! Resetting...\r\n',
        b'I2C and sensor reset complete\r\n',
        DOC_LINE.encode(),
        b'\r\n',
    ]
    data = b''.join(lines)
    for chunk in (1, 7, len(data)):
        stream = TelemetryStream(n_sensors=2)
        items = [
            item for i in range(0, len(data), chunk) for item in stream.feed(data[i : i + chunk])
        ]
        kinds = [type(item).__name__ for item in items]
        assert kinds == ['InfoMessage'] * 3 + ['TelemetrySample'] + ['InfoMessage'] * 2 + [
            'TelemetrySample'
        ]
        assert items[0] == InfoMessage(
            'Sensor on channel 7 initialized successfully.', Severity.INFO
        )
        assert items[4].severity == Severity.WARN
        assert items[5].severity == Severity.INFO
        assert (
            stream.stats.samples == 2
            and stream.stats.messages == 5
            and stream.stats.malformed == 0
        )


def test_partial_first_line_is_malformed_not_a_message():
    stream = TelemetryStream()
    data = DOC_LINE.encode()
    items = stream.feed(data[20:] + data + data)
    assert [type(i) for i in items] == [TelemetrySample, TelemetrySample]
    assert stream.stats.malformed == 1
    assert stream.stats.dropped_bytes == len(data) - 20
    assert stream.n_sensors == 2  # inferred from the first sample


def test_sensor_count_change_is_malformed():
    stream = TelemetryStream()
    one = format_telemetry_line(0.0, np.zeros(4), np.zeros((1, 3)))
    two = format_telemetry_line(0.0, np.zeros(4), np.zeros((2, 3)))
    assert len(stream.feed(one + two + one)) == 2
    assert stream.stats.malformed == 1


def test_overlong_line_is_dropped():
    stream = TelemetryStream()
    assert stream.feed(b'x' * 5000) == []
    items = stream.feed(b'yyy\r\n' + DOC_LINE.encode())
    assert len(items) == 1 and isinstance(items[0], TelemetrySample)
    assert stream.stats.malformed == 1
    assert stream.stats.dropped_bytes == 5000 + 5


def test_bad_n_sensors():
    with pytest.raises(ValueError, match='n_sensors must be a positive int or None, got 0'):
        TelemetryStream(0)
