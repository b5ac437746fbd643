"""The driver's /diagnostics status, without ROS: level, rates, counters."""

import numpy as np
import pytest

from maglev_ros.hardware.board_link import BoardLink
from maglev_ros.hardware.board_stream import BoardStream
from maglev_ros.hardware.command_guard import CommandGuard
from maglev_ros.hardware.driver_health import COUNTERS, DriverHealth, driver_counters
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.serial_link import Backoff, SerialLink
from maglev_ros.health import ERROR, OK, WARN


class Log:
    def info(self, text, **_):
        pass

    warning = error = info


def parts(tmp_path):
    scaling = CurrentScaling(1000.0)
    link = BoardLink(
        SerialLink(str(tmp_path / 'port'), 9600),
        BoardStream('v2x', 1, scaling),
        Backoff(0.1, 0.2),
        Log(),
        writes=True,
    )
    return link, CommandGuard(scaling, 1.0, 0.1, enabled=True)


def test_levels_follow_link_and_timeout(tmp_path):
    link, guard = parts(tmp_path)
    health = DriverHealth('v2x', now=0.0)
    report = health.report(link, guard, now=1.0)
    assert (report.level, report.message) == (ERROR, 'board link connecting')
    link.state = 'connected'
    assert health.report(link, guard, now=2.0).level == OK
    guard.command([0.1, 0.1, 0.1, 0.1], now_ns=0)
    assert guard.check_timeout(now_ns=200_000_000) == pytest.approx(0.2)
    report = health.report(link, guard, now=3.0)
    assert (report.level, report.message) == (WARN, 'command timeout: zero currents')


def test_rates_over_the_interval_and_every_counter(tmp_path):
    link, guard = parts(tmp_path)
    health = DriverHealth('v4x', now=10.0)
    link.counts['records'] = 500
    link.counts['commands_sent'] = 50
    link.applied = np.array([1, -2, 3, -4])
    link.last_info = 'hello'
    values = health.report(link, guard, now=10.5).values
    assert values['records/s'] == '1000.0' and values['command rate (1/s)'] == '100.0'
    assert values['applied PWM (counts)'] == '1 -2 3 -4'
    assert values['last board message'] == 'hello' and values['enabled'] == 'True'
    assert values['field kind'] == 'baseline and feedthrough removed (V4x)'
    assert list(values)[-len(COUNTERS) :] == [c.replace('_', ' ') for c in COUNTERS]
    assert values['records'] == '500'
    link.counts['records'] = 600
    assert health.report(link, guard, now=11.5).values['records/s'] == '100.0'
    assert list(driver_counters(link, guard)) == list(COUNTERS)


def test_resync_rate_warns_above_the_threshold(tmp_path):
    from maglev_ros.hardware.driver_health import RESYNC_WARN_PER_S

    link, guard = parts(tmp_path)
    link.state = 'connected'
    health = DriverHealth('v2x', now=0.0)
    decoder = link.stream.decoder
    decoder._resyncs = int(RESYNC_WARN_PER_S)  # exactly the threshold over 1 s: OK
    decoder._dropped = 240
    report = health.report(link, guard, now=1.0)
    assert report.level == OK
    assert report.values['resyncs/s'] == f'{RESYNC_WARN_PER_S:.1f}'
    assert report.values['dropped bytes/s'] == '240.0'
    decoder._resyncs += 143  # one fault every 7 ms
    decoder._dropped += 3400
    report = health.report(link, guard, now=2.0)
    assert report.level == WARN
    assert report.message.startswith('corrupted link: 143 resyncs/s, 3400 bytes/s dropped')
    assert health.report(link, guard, now=3.0).level == OK  # the next interval is clean


def test_a_corrupted_stream_shows_in_the_diagnostics(tmp_path):
    from maglev_ros.hardware.v2x_stream import pack_records

    link, guard = parts(tmp_path)
    link.state = 'connected'
    health = DriverHealth('v2x', now=0.0)
    n = 10_000  # 2 s of records, the tail of one record lost every 7 ms
    rng = np.random.default_rng(0)
    stamps = 1_000_000 + 200 * np.arange(n)
    field = rng.normal(0.0, 30.0, (n, 1, 3)).astype(np.float32)
    records = [
        pack_records(stamps[i : i + 1], field[i : i + 1], np.zeros((1, 4))) for i in range(n)
    ]
    for at in range(17, n - 2, 35):
        records[at] = records[at][: -int(rng.integers(1, 24))]
    stream = b''.join(records)
    published = []
    for k in range(0, len(stream), 120):
        out = link.stream.feed(stream[k : k + 120], host_ns=k * 10_000)
        published.append(out.values)
    values = np.concatenate(published)
    damaged = set(range(17, n - 2, 35))
    expected = field.reshape(n, 3).astype(np.float64) * 1e-3  # T, as the stream converts
    where = {row: i for i, row in enumerate(map(tuple, expected))}
    index = [where[tuple(row)] for row in values[:, :3]]  # KeyError: a foreign sample
    assert not damaged & set(index) and np.all(np.diff(index) > 0)
    assert len(index) >= 0.99 * (n - len(damaged))
    report = health.report(link, guard, now=2.0)
    assert report.level == WARN and report.message.startswith('corrupted link: 143 resyncs/s')
    assert float(report.values['resyncs/s']) == pytest.approx(143, abs=1)
