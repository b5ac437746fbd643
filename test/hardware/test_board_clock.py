import numpy as np
import pytest

from maglev_ros.hardware.board_clock import BoardClock


def observe_stream(clock, seconds, drift=0.0, offset_ns=5 * 10**17, seed=0, max_latency_us=800):
    rng = np.random.default_rng(seed)
    for board_us in range(1_000_000, 1_000_000 + int(seconds * 1e6), 1000):  # one read per ms
        latency = int(rng.uniform(0, max_latency_us) * 1000)
        host = offset_ns + round(board_us * 1000 * (1 + drift)) + latency
        clock.observe(board_us, host)
    return offset_ns


def test_offset_from_the_fastest_read():
    clock = BoardClock()
    clock.observe(1_000, 2_000_000 + 500_000)  # 0.5 ms latency
    clock.observe(2_000, 3_000_000 + 50_000)  # 50 us latency: the better estimate
    np.testing.assert_array_equal(clock.to_host([3_000]), [4_050_000])


def test_drift_is_estimated():
    clock = BoardClock(bucket=1.0, buckets=30)
    offset = observe_stream(clock, 12.0, drift=100e-6)
    assert clock.drift == pytest.approx(100e-6, abs=10e-6)
    board = np.array([13_000_000])
    truth = offset + round(13_000_000 * 1000 * (1 + 100e-6))
    err_us = (clock.to_host(board)[0] - truth) / 1000
    assert 0 <= err_us < 100  # within the fastest reads' latency


def test_stamps_never_go_backwards():
    clock = BoardClock()
    clock.observe(1_000_000, 10**12 + 900_000)  # slow first read
    first = clock.to_host(1_000_000 + 200 * np.arange(5))
    clock.observe(1_001_000, 10**12 + 1_000_000)  # 0.9 ms faster: the line drops
    second = clock.to_host(1_000_800 + 200 * np.arange(1, 6))
    stamps = np.concatenate([first, second])
    assert np.all(np.diff(stamps) > 0)
    assert second[0] == first[-1] + 1  # held back, not jumping backwards
    assert second[-1] == 10**12 + 1_800_000  # the new line: 1_001_800 us + new offset


def test_needs_an_observation_and_validates():
    with pytest.raises(ValueError, match='needs an observation'):
        BoardClock().to_host([0])
    with pytest.raises(ValueError, match='bucket must be > 0 s, got 0'):
        BoardClock(bucket=0)
    with pytest.raises(ValueError, match='buckets must be >= 3, got 2'):
        BoardClock(buckets=2)


def test_reset():
    clock = BoardClock()
    observe_stream(clock, 4.0, drift=50e-6)
    clock.reset()
    assert clock.observations == 0 and clock.drift == 0.0
    with pytest.raises(ValueError):
        clock.to_host([0])


def test_scalar_and_vector_paths_agree():
    rng = np.random.default_rng(3)
    a, b = BoardClock(), BoardClock()
    board = 1_000_000
    for _ in range(300):
        host = 7 * 10**17 + round(board * 1000 * (1 + 37e-6)) + int(rng.uniform(0, 9e5))
        a.observe(board, host)
        b.observe(board, host)
        times = board - 200 * np.arange(int(rng.integers(1, 40)))[::-1]
        small = np.concatenate([a.to_host(times[i : i + 5]) for i in range(0, len(times), 5)])
        large = b.to_host(times) if len(times) > 16 else None
        if large is not None:
            np.testing.assert_array_equal(small, large)
        else:
            b.to_host(times)  # keep both clocks' last stamp in step
            assert b._last_stamp_ns == a._last_stamp_ns
        board += 1000 + int(rng.integers(0, 3000))
