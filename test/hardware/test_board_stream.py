"""The board stream: decode, units, board clock and catch-up, without ROS."""

import numpy as np
import pytest

from maglev_ros.hardware.board_stream import MAX_HELD_RECORDS, BoardStream, caught_up_records
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.v2x_stream import pack_records
from maglev_ros.hardware.v4x_telemetry import Severity, format_telemetry_line

HOST0 = 1_700_000_000 * 10**9  # host time of board time 0, ns
PERIOD_NS = 200_000
SCALING = CurrentScaling(1000.0)


def records(n, n_sensors=1, seed=0):
    """n V2x records from board time 0: fields (mT) and PWM counts, and their bytes."""
    rng = np.random.default_rng(seed)
    field = rng.normal(0.0, 5.0, (n, n_sensors, 3)).astype(np.float32)
    pwm = rng.integers(-4000, 4000, (n, 4))
    return field, pwm, pack_records(200 * np.arange(n), field, pwm)


def test_v2x_fields_in_tesla_and_currents_from_pwm():
    field, pwm, data = records(50, n_sensors=2)
    stream = BoardStream('v2x', 2, SCALING, confirm_records=False)
    size = len(data) // 50
    outs = [  # bursts of 5 records, read every 1 ms: caught up from the first read on
        stream.feed(data[k * size : (k + 5) * size], HOST0 + (k + 5) * PERIOD_NS)
        for k in range(0, 50, 5)
    ]
    assert [len(out) for out in outs] == [5] * 10
    values = np.concatenate([out.values for out in outs])
    assert values.shape == (50, 10)
    np.testing.assert_array_equal(values[:, :6], field.reshape(50, 6).astype(float) * 1e-3)
    np.testing.assert_allclose(values[:, 6:], pwm / 1000.0)
    assert np.all(np.diff(np.concatenate([out.stamps_ns for out in outs])) > 0)


def test_v4x_lines_and_info_messages():
    current = np.array([0.4, -0.4, 0.2, -0.2])
    field = np.array([[1.0, 2.0, 3.0], [-1.0, -2.0, -3.0]])
    data = b''.join(format_telemetry_line(0.001 * k, current, field) for k in range(4))
    data += b'I2C and sensor reset complete\r\n' + b'Sensor freeze detected\r\n'
    stream = BoardStream('v4x', 2, SCALING)
    out = stream.feed(data, HOST0)
    assert len(out) == 4
    np.testing.assert_allclose(out.values[0], [*(field.ravel() * 1e-3), *current], atol=1e-12)
    assert [(i.text, i.severity) for i in out.infos] == [
        ('I2C and sensor reset complete', Severity.INFO),
        ('Sensor freeze detected', Severity.WARN),
    ]


def read_with_a_backlog(stream, n_records, start_delay_ns, chunk):
    """The board streams from HOST0; the first read comes ``start_delay_ns`` later.

    Reads bring at most ``chunk`` records (what the OS buffer hands over) and
    come every 0.2 ms while a backlog is drained, every 1 ms after; a record
    is readable 0.1 ms after its board time. Returns each read's output.
    """
    _, _, data = records(n_records)
    size = len(data) // n_records
    outputs, taken, host = [], 0, start_delay_ns
    while taken < n_records:
        available = min(n_records, (host - 100_000) // PERIOD_NS + 1)
        take = min(available - taken, chunk)
        outputs.append(
            (take, stream.feed(data[taken * size : (taken + take) * size], HOST0 + host))
        )
        taken += take
        host += 200_000 if take == chunk else 1_000_000
    return outputs


def test_a_backlog_at_start_is_stamped_evenly_and_kept():
    # the first read comes 0.5 s after the board started (a busy start-up): the first
    # reads bring a backlog whose newest record is old; the stream keeps the samples
    # until the link has caught up, then stamps them all with the caught-up clock:
    # every record is published, 200 us apart from the first one on (no held-back or
    # stepped stamps), and the first stamp is the board's start
    stream = BoardStream('v2x', 1, SCALING)
    outputs = read_with_a_backlog(stream, 10_000, start_delay_ns=500_000_000, chunk=170)
    first = next(i for i, (_, out) in enumerate(outputs) if len(out))
    backlog = [take for take, _ in outputs[:first]]
    assert len(backlog) > 10 and min(backlog) > stream.caught_up_records
    assert outputs[first][0] <= stream.caught_up_records  # published once caught up
    stamps = np.concatenate([out.stamps_ns for _, out in outputs])
    steps = np.diff(stamps)
    # board steps of 200 us through the clock's drift and slewing (2 %)
    assert np.all(np.abs(steps - 200_000) <= 0.02 * 200_000 + 100), steps.min()
    assert stamps[-1] - stamps[0] > 10**9  # over a second: the backlog is in
    assert abs(stamps[0] - HOST0) < 1_000_000  # the first stamps are right
    assert len(stamps) == stream.decoder_stats.records == 10_000 - 1  # one held back


def test_a_link_that_never_catches_up_publishes_anyway():
    stream = BoardStream('v2x', 1, SCALING, confirm_records=False)
    _, _, data = records(MAX_HELD_RECORDS + 200)
    size = len(data) // (MAX_HELD_RECORDS + 200)
    published, chunk = 0, 100  # every read brings more than a caught-up read
    for k in range(0, MAX_HELD_RECORDS + 200, chunk):
        published += len(stream.feed(data[k * size : (k + chunk) * size], HOST0 + k * 10**6))
        assert published in (0, k + chunk)  # all held, then all published
    assert published == MAX_HELD_RECORDS + 200 and not stream.catching_up


def test_reconnect_catches_up_again_and_keeps_the_decoder_counts():
    stream = BoardStream('v2x', 1, SCALING, read_interval=0.002)
    assert stream.caught_up_records == caught_up_records(0.002) == 5 * 3 + 1
    _, _, data = records(40)
    half = len(data) // 2
    stream.feed(data[:half] + b'garbage' + data[half:], HOST0)
    resyncs, dropped = stream.resyncs, stream.dropped_bytes
    assert resyncs >= 1 and dropped >= 7
    stream.disconnect()
    stream.connect()
    assert stream.catching_up and (stream.resyncs, stream.dropped_bytes) == (resyncs, dropped)
    assert stream.decoder_stats.records == 0  # a new connection's decoder
    stream.feed(data[:half] + b'xx' + data[half:], HOST0 + 10**9)
    assert stream.decoder_stats.resyncs >= 1
    assert stream.resyncs == resyncs + stream.decoder_stats.resyncs
    assert stream.dropped_bytes == dropped + stream.decoder_stats.dropped_bytes


def test_unknown_firmware():
    with pytest.raises(ValueError, match="firmware must be 'v2x' or 'v4x', got 'v9x'"):
        BoardStream('v9x', 1, SCALING)
