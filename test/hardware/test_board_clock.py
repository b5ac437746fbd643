import numpy as np
import pytest

from maglev_ros.hardware.board_clock import BoardClock

SLEW = 0.02  # the default: 4 us per 200 us sample


def observe_stream(clock, seconds, drift=0.0, offset_ns=5 * 10**17, seed=0, max_latency_us=800):
    rng = np.random.default_rng(seed)
    for board_us in range(1_000_000, 1_000_000 + int(seconds * 1e6), 1000):  # one read per ms
        latency = int(rng.uniform(0, max_latency_us) * 1000)
        host = offset_ns + round(board_us * 1000 * (1 + drift)) + latency
        clock.observe(board_us, host)
    return offset_ns


def board_run(
    clock, seconds, drift=50e-6, offset_ns=5 * 10**17, seed=0, batch=(1, 40), latency_steps=True
):
    """A board clock running ``drift`` fast, read in batches with random latency.

    The board samples every 200 us; each read returns 1..39 records and is
    observed (newest record, host time of the read) before its records are
    mapped, as the driver does. The latency is 20 us plus an exponential tail
    (mean 300 us), with a rare fast read (0..5 us: a new minimum) and, if
    ``latency_steps``, whole seconds of slow link (+600 us) that shift the
    bucket minima up and down.

    Returns
    -------
    board : ndarray of int64, shape (n,)
        Board times, us.
    stamps : ndarray of int64, shape (n,)
        Mapped stamps, ns.
    truth : ndarray of int64, shape (n,)
        Host time of each sample (zero latency), ns.
    pending : ndarray of int64, shape (reads,)
        ``pending_ns`` after each observation (the correction the read's
        records are mapped with).
    drifts : ndarray of float, shape (n,)
        The estimated drift each sample was mapped with.
    """
    rng = np.random.default_rng(seed)
    board_us, end = 1_000_000, 1_000_000 + int(seconds * 1e6)
    boards, stamps, pending, drifts = [], [], [], []
    while board_us < end:
        times = board_us + 200 * np.arange(int(rng.integers(*batch)))
        board_us = int(times[-1]) + 200
        latency_us = 20 + rng.exponential(300)
        if latency_steps and (board_us // 1_000_000) % 4 == 3:
            latency_us += 600
        if rng.random() < 0.002:
            latency_us = rng.uniform(0, 5)
        host = offset_ns + round(int(times[-1]) * 1000 * (1 + drift)) + int(latency_us * 1000)
        clock.observe(int(times[-1]), host)
        pending.append(clock.pending_ns)
        boards.append(times)
        stamps.append(clock.to_host(times))
        drifts.append(np.full(times.size, clock.drift))
    board = np.concatenate(boards)
    truth = offset_ns + np.rint(board * 1000 * (1 + drift)).astype(np.int64)
    return board, np.concatenate(stamps), truth, np.array(pending), np.concatenate(drifts)


def test_offset_from_the_fastest_read():
    clock = BoardClock()
    clock.observe(1_000, 2_000_000 + 500_000)  # 0.5 ms latency
    clock.observe(2_000, 3_000_000 + 50_000)  # 50 us latency: the better estimate
    np.testing.assert_array_equal(clock.to_host([3_000]), [4_050_000])  # nothing to slew yet


def test_first_observation_sets_the_offset():
    # a host clock 1.7e18 ns ahead: no slewing from zero, the first stamp is on the line
    clock = BoardClock()
    clock.observe(5_000_000, 1_700_000_000_000_000_000 + 5_000_000_000 + 120_000)
    stamps = clock.to_host(4_000_000 + 200 * np.arange(20))
    np.testing.assert_array_equal(
        stamps, 1_700_000_000_000_000_000 + 120_000 + 1000 * (4_000_000 + 200 * np.arange(20))
    )
    assert clock.pending_ns == 0


def test_drift_is_estimated():
    clock = BoardClock(bucket=1.0, buckets=30)
    offset = observe_stream(clock, 12.0, drift=100e-6)
    assert clock.drift == pytest.approx(100e-6, abs=10e-6)
    board = np.array([13_000_000])
    truth = offset + round(13_000_000 * 1000 * (1 + 100e-6))
    err_us = (clock.to_host(board)[0] - truth) / 1000
    assert abs(err_us) < 10  # the envelope of the fastest reads (1000 per bucket)


def test_a_lower_minimum_is_slewed_not_stepped():
    clock = BoardClock()
    clock.observe(1_000_000, 10**12 + 900_000)  # slow first read
    first = clock.to_host(1_000_000 + 200 * np.arange(5))
    np.testing.assert_array_equal(np.diff(first), 200_000)
    clock.observe(1_001_000, 10**12 + 1_000_000)  # 0.9 ms faster: the line drops
    assert clock.pending_ns == -900_000
    board = 1_000_800 + 200 * np.arange(1, 301)
    second = clock.to_host(board)
    diffs = np.diff(np.concatenate([first, second]))
    # 4 us less per sample until the 0.9 ms are absorbed (225 samples), then the line
    np.testing.assert_array_equal(diffs[4:229], 196_000)
    np.testing.assert_array_equal(diffs[229:], 200_000)
    np.testing.assert_array_equal(second[225:], 10**12 - 10**9 + 1000 * board[225:])
    assert clock.pending_ns == 0


def test_a_higher_line_is_slewed_forwards():
    # 10 ms buckets, three of them fitted: the fast bucket drops out of the window and
    # the line rises by 300 us; the stamps move later by at most 2 % of the spacing
    # (scaled by the estimated drift, here the tilt of the line while it rises)
    clock = BoardClock(bucket=0.01, buckets=3)
    stamps, board, drift = [], [], []
    for k in range(150):  # one read per ms
        b = 1_000_000 + 1000 * k
        clock.observe(b, 10**12 + 1000 * b + (0 if k < 10 else 300_000))
        times = b - 800 + 200 * np.arange(5)
        board.append(times)
        stamps.append(clock.to_host(times))
        drift.append(np.full(5, clock.drift))
    stamps, board, drift = np.concatenate(stamps), np.concatenate(board), np.concatenate(drift)
    diffs = np.diff(stamps)
    assert np.abs(diffs - 200_000 * (1 + drift[1:])).max() <= SLEW * 200_000 + 3
    assert diffs.max() > 200_000 and diffs.min() >= 200_000  # forwards only
    assert np.sum(diffs - 200_000) == 300_000
    np.testing.assert_array_equal(stamps[-50:], 10**12 + 1000 * board[-50:] + 300_000)
    assert clock.pending_ns == 0 and clock.drift == 0.0


def test_a_correction_beyond_max_slew_jumps():
    clock = BoardClock(max_slew=0.05)
    clock.observe(1_000_000, 10**12 + 60_000_000)  # 60 ms late: e.g. a stalled first read
    first = clock.to_host(1_000_000 + 200 * np.arange(5))
    clock.observe(1_001_000, 10**12 + 1_000_000)  # 60 ms lower: not slewed over 3 s
    assert clock.pending_ns == 0
    board = 1_000_800 + 200 * np.arange(1, 400)
    second = clock.to_host(board)
    line = 10**12 - 10**9 + 1000 * board
    held = second > line
    # held back 1 ns apart (never backwards) until the line passes, then the line
    np.testing.assert_array_equal(second[held], first[-1] + 1 + np.arange(held.sum()))
    assert 295 <= held.sum() <= 300  # 60 ms of board time
    np.testing.assert_array_equal(second[~held], line[~held])
    # a correction within max_slew is slewed
    near = BoardClock(max_slew=0.07)
    near.observe(1_000_000, 10**12 + 60_000_000)
    near.to_host([1_000_000])
    near.observe(1_001_000, 10**12 + 1_000_000)
    assert near.pending_ns == -60_000_000


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_board_run_never_steps(seed):
    # latency changing second by second (slow link for 1 s in 4) and rare fast reads:
    # the fitted line moves up and down all the time, the stamps never step
    drift = 50e-6
    clock = BoardClock()
    board, stamps, _, pending, drifts = board_run(clock, 40.0, drift=drift, seed=seed)
    diffs = np.diff(stamps)
    assert np.all(diffs > 0)
    assert np.all(np.diff(board) == 200)
    # every spacing within 2 % of the board's 200 us scaled by the estimated drift, to
    # the rounding (ns) ...
    deviation = np.abs(diffs - 200_000 * (1 + drifts[1:]))
    assert deviation.max() <= SLEW * 200_000 + 3
    assert deviation.max() >= SLEW * 200_000 - 3  # the slewing was needed and used
    assert np.any(pending < 0)  # a correction was pending when a read was mapped
    # ... and of the true drift within the estimate's error (early fits: < 0.5 per mille)
    assert np.abs(diffs - 200_000 * (1 + drift)).max() <= SLEW * 200_000 + 100


@pytest.mark.parametrize('latency_steps', [False, True])
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_board_run_converges_to_the_true_offset_and_drift(seed, latency_steps):
    drift = 50e-6
    clock = BoardClock()
    board, stamps, truth, _, _ = board_run(
        clock, 40.0, drift=drift, seed=seed, latency_steps=latency_steps
    )
    assert np.all(np.diff(stamps) > 0)
    assert np.abs(np.diff(stamps) - 200_000 * (1 + drift)).max() <= SLEW * 200_000 + 100
    assert clock.drift == pytest.approx(drift, abs=0.5e-6)
    err_us = (stamps - truth) / 1000
    first_s, last_s = board < board[0] + 1_000_000, board >= board[-1] - 10_000_000
    assert np.abs(err_us[first_s]).max() > 50  # the first reads were slow ...
    # ... then the envelope of the fast reads (0..5 us, a few per bucket), slow seconds
    # of link or not
    assert np.abs(err_us[last_s]).max() < 10


def test_needs_an_observation_and_validates():
    with pytest.raises(ValueError, match='needs an observation'):
        BoardClock().to_host([0])
    with pytest.raises(ValueError, match='bucket must be > 0 s, got 0'):
        BoardClock(bucket=0)
    with pytest.raises(ValueError, match='buckets must be >= 3, got 2'):
        BoardClock(buckets=2)
    with pytest.raises(ValueError, match=r'slew must be a fraction in \[1e-6, 0.1\], got 0.2'):
        BoardClock(slew=0.2)
    with pytest.raises(ValueError, match='slew must be a fraction'):
        BoardClock(slew=0.0)
    with pytest.raises(ValueError, match='max_slew must be > 0 s, got -1'):
        BoardClock(max_slew=-1)


def test_reset_keeps_the_parameters():
    clock = BoardClock(slew=0.01)
    observe_stream(clock, 4.0, drift=50e-6)
    clock.reset()
    assert clock.observations == 0 and clock.drift == 0.0 and clock.pending_ns == 0
    assert clock.slew == 0.01
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


def test_scalar_and_vector_paths_agree_while_slewing():
    # the same board run mapped in batches of 17..400 (numpy) and one sample at a time
    # (scalar): bit-for-bit the same stamps, through many corrections in both directions
    # the latency floor alternates between 5 and 400 us every 0.5 s: with three 0.1 s
    # buckets the line drops and rises again
    whole, single = BoardClock(bucket=0.1, buckets=3), BoardClock(bucket=0.1, buckets=3)
    rng = np.random.default_rng(11)
    board_us, pending, out_whole, out_single = 1_000_000, [], [], []
    for _ in range(600):
        times = board_us + 200 * np.arange(int(rng.integers(17, 60)))
        board_us = int(times[-1]) + 200
        floor_us = 5 if (board_us // 500_000) % 2 else 400
        host = (
            10**18
            + round(int(times[-1]) * 1000 * (1 - 80e-6))
            + int((floor_us + rng.exponential(50)) * 1000)
        )
        whole.observe(int(times[-1]), host)
        single.observe(int(times[-1]), host)
        pending.append(whole.pending_ns)  # the correction these samples are mapped with
        out_whole.append(whole.to_host(times))
        out_single.append(
            np.concatenate([single.to_host(times[i : i + 1]) for i in range(times.size)])
        )
        assert single.pending_ns == whole.pending_ns
    np.testing.assert_array_equal(np.concatenate(out_single), np.concatenate(out_whole))
    pending = np.array(pending)
    assert np.count_nonzero(pending > 0) > 20 and np.count_nonzero(pending < 0) > 20


def test_a_host_stall_does_not_tilt_the_line():
    # the host stalls for 1.5 s, then catches up reading at most 40 records (8 ms of
    # board time) per 1 ms: every read of two buckets returns old records, their
    # fastest reads are hundreds of ms late; the lower envelope ignores them: no
    # jump, no step, the drift stays right (least squares jumped 0.6 s, then tilted
    # the spacing by 1.5 %)
    drift = 20e-6
    clock = BoardClock()
    rng = np.random.default_rng(9)
    board_us, boards, stamps, latest = 1_000_000, [], [], []
    offset = 10**18
    for k in range(20_000):  # one read per ms of host time (at a random phase): 20 s
        host_us = 1_000_000 + 1000 * k + int(rng.integers(0, 1000))
        if 12_000_000 <= host_us < 13_500_000:
            continue  # stalled: nothing read
        newest = int((host_us - 30) / (1 + drift)) // 200 * 200  # 30 us of transfer
        times = np.arange(board_us, newest + 1, 200)[:40]
        if times.size == 0:
            continue
        board_us = int(times[-1]) + 200
        clock.observe(int(times[-1]), offset + 1000 * host_us + int(rng.exponential(100_000)))
        boards.append(times)
        stamps.append(clock.to_host(times))
        latest.append(newest - int(times[-1]))
    assert max(latest) > 1_000_000 and latest[-1] == 0  # 1 s behind, then caught up
    board, stamps = np.concatenate(boards), np.concatenate(stamps)
    assert np.all(np.diff(board) == 200)
    diffs = np.diff(stamps)
    assert np.abs(diffs - 200_000 * (1 + drift)).max() <= SLEW * 200_000 + 20
    assert clock.drift == pytest.approx(drift, abs=1e-6)
    truth = offset + np.rint(board * 1000 * (1 + drift)).astype(np.int64)
    err_us = (stamps - truth) / 1000
    assert np.all(np.abs(err_us[board > board[-1] - 5_000_000]) < 50)


def test_a_stalled_bucket_at_the_start_is_left_out():
    # 3 s into a session (three complete buckets), the last of them was read only after
    # a 0.85 s stall, and so were the first 0.3 s of the next bucket (the host catching
    # up): as the newest point of a short window it is a hull vertex next to the mean
    # and would tilt the line by tens of percent; it is above the others by far more
    # than max_drift allows, so it is left out
    rng = np.random.default_rng(12)
    clock = BoardClock()
    boards, stamps, drifts = [], [], []
    for k in range(4_500):  # one read per ms of board time, 5 records each
        times = 1_000_000 + 1000 * k + 200 * np.arange(-4, 1)
        late_ns = 850_000_000 if 3_000_000 <= times[-1] < 4_300_000 else 0
        clock.observe(
            int(times[-1]),
            10**18 + 1000 * int(times[-1]) + late_ns + int(rng.uniform(50_000, 300_000)),
        )
        boards.append(times)
        stamps.append(clock.to_host(times))
        drifts.append(clock.drift)
    board, stamps = np.concatenate(boards), np.concatenate(stamps)
    assert np.abs(drifts).max() < 5e-6
    assert np.abs(np.diff(stamps) - 200_000).max() <= SLEW * 200_000 + 5
    err_us = (stamps - 10**18 - 1000 * board) / 1000
    assert np.all((err_us > 0) & (err_us < 300))


def test_max_drift_is_validated():
    with pytest.raises(ValueError, match=r'max_drift must be in \(0, 0.1\], got 0'):
        BoardClock(max_drift=0)
