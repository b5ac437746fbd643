"""The simulation session: pacing, lockstep commands, timeouts, crashes, without ROS."""

import numpy as np
import pytest

from maglev_ros.physics import CoilDynamics, SensorEffects, Simulator
from maglev_ros.physics.session import (
    MAX_BACKLOG_S,
    PAUSED_POLL_S,
    CommandError,
    SimulationSession,
)

RATE = 5000.0
DT = 1.0 / RATE
FALLING = [0.001, 0.0, 0.0365] + [0.0] * 9  # free magnet just above the base


def simulator(v2, **kwargs):
    kwargs.setdefault('magnet', 'fixed')
    return Simulator(v2, RATE, **kwargs)


def session(v2, mode='lockstep', sim_kwargs=None, **kwargs):
    return SimulationSession(simulator(v2, **(sim_kwargs or {})), mode, now=0.0, **kwargs)


def test_lockstep_steps_one_sample_per_command_in_order(v2):
    rng = np.random.default_rng(0)
    commands = rng.uniform(-0.5, 0.5, (20, 4))
    s = session(v2, sim_kwargs={'magnet': 'free', 'seed': 3})
    assert s.command(commands[0], now=0.0) is None  # before the first sample: ignored
    first = s.start(now=0.0)
    assert first.indices.tolist() == [0] and first.stamps_ns.tolist() == [0]
    reference = simulator(v2, magnet='free', seed=3)
    np.testing.assert_array_equal(first.readings[0], reference.reset())
    for k, command in enumerate(commands, start=1):
        batch = s.command(command, now=0.0)
        assert batch.indices.tolist() == [k]  # a burst of one
        assert batch.stamps_ns.tolist() == [k * 200_000]
        np.testing.assert_array_equal(batch.readings[0], reference.step(command))
        np.testing.assert_array_equal(batch.states[0], reference.state)
        np.testing.assert_array_equal(batch.currents[0], reference.currents)
    assert s.counters['samples'] == 21 and s.counters['commands'] == 21
    assert s.counters['timeouts'] == 0 and s.last_stamp_ns == 20 * 200_000


def test_lockstep_queues_commands_while_paused(v2):
    s = session(v2, paused=True)
    s.start(now=0.0)
    assert s.command([0.1, 0, 0, 0], now=1.0) is None
    assert s.command([0.2, 0, 0, 0], now=1.0) is None
    assert s.check_timeout(now=100.0) is None  # paused: no timeout
    batch = s.set_paused(False, now=2.0)
    assert batch.indices.tolist() == [1, 2]
    np.testing.assert_array_equal(batch.currents[:, 0], [0.1, 0.2])  # ideal coils
    assert s.waiting_since == 2.0


def test_lockstep_pause_after_steps_exactly_up_to_a_sample(v2):
    s = session(v2, paused=True)
    s.start(now=0.0)
    for k in range(5):
        s.command([0.01 * k, 0, 0, 0], now=1.0)  # queued while paused
    s.pause_after(3)
    batch = s.set_paused(False, now=2.0)
    assert batch.indices.tolist() == [1, 2, 3] and s.paused  # sample 3 is published
    assert s.check_timeout(now=100.0) is None  # paused: nothing more
    batch = s.set_paused(False, now=3.0)  # resumed: the queued commands, no further limit
    assert batch.indices.tolist() == [4, 5] and not s.paused
    s.pause_after(5)  # already stepped: pauses at once
    assert s.paused and s.command([0, 0, 0, 0], now=4.0) is None


def test_realtime_pause_after_ends_the_burst(v2):
    s = session(v2, 'realtime', pace_period=0.001)
    s.start(now=0.0)
    s.pause_after(7)
    assert s.pace(now=0.0)[0] is None  # pacing starts
    batch, _ = s.pace(now=0.005)  # 25 samples due
    assert batch.indices.tolist()[-1] == 7 and s.paused


def test_lockstep_timeout_holds_the_last_command(v2):
    s = session(v2, command_timeout=0.1)
    s.start(now=0.0)
    s.command([0.2, 0.0, 0.0, 0.0], now=0.0)
    assert s.check_timeout(now=0.1) is None  # not past the timeout
    held = s.check_timeout(now=0.15)
    assert held.indices.tolist() == [2]
    np.testing.assert_array_equal(held.currents[0], [0.2, 0.0, 0.0, 0.0])
    assert s.check_timeout(now=0.2) is None  # the wait restarts at the held sample
    assert s.check_timeout(now=0.26).indices.tolist() == [3]
    assert s.counters['timeouts'] == 2


@pytest.mark.parametrize('values', [[0.0] * 3, [0.0, np.nan, 0.0, 0.0], [[0.0] * 4]])
def test_rejected_commands_change_nothing(v2, values):
    s = session(v2, mode='realtime')
    with pytest.raises(CommandError, match=r'need 4 finite currents \(x\+, x-, y\+, y-\)'):
        s.command(values, now=0.0)
    assert s.counters['commands_rejected'] == 1 and s.counters['commands'] == 0


def test_realtime_paces_bursts_to_the_wall_clock(v2):
    s = session(v2, mode='realtime', pace_period=0.001)
    assert s.start(now=0.0).indices.tolist() == [0]
    batch, wait = s.pace(0.0)
    assert batch is None and wait == pytest.approx(0.001)  # a whole burst is due then
    batch, wait = s.pace(0.0009)
    assert batch is None and wait == pytest.approx(0.0001)
    batch, wait = s.pace(0.0012)
    assert batch.indices.tolist() == [1, 2, 3, 4, 5]
    assert wait == pytest.approx(0.0008)  # from now to the next burst, at 0.002 s
    np.testing.assert_array_equal(np.diff(batch.stamps_ns), 200_000)
    batch, _ = s.pace(0.0031)  # late: everything due is stepped at once
    assert batch.indices.tolist() == list(range(6, 16))
    assert s.counters['overruns'] == 0


def test_realtime_max_batch_catches_up_a_burst_at_a_time(v2):
    s = session(v2, mode='realtime', pace_period=0.001)
    s.max_batch = s.burst  # a loop closed in the stepping thread answers each burst
    s.start(now=0.0)
    s.pace(0.0)
    batch, wait = s.pace(0.0031)  # 15 samples due: one burst now, the rest at once after
    assert batch.indices.tolist() == [1, 2, 3, 4, 5] and wait == 0.0
    batch, wait = s.pace(0.0031)
    assert batch.indices.tolist() == [6, 7, 8, 9, 10] and wait == 0.0
    batch, wait = s.pace(0.0031)
    assert batch.indices.tolist() == [11, 12, 13, 14, 15]
    assert wait == pytest.approx(0.0009)  # caught up: the next burst at 0.004 s


def test_realtime_drops_a_backlog(v2):
    s = session(v2, mode='realtime')
    s.start(now=0.0)
    s.pace(0.0)
    batch, _ = s.pace(MAX_BACKLOG_S + 0.05)  # far behind: one sample, pacing restarts
    assert len(batch) == 1 and s.counters['overruns'] == 1
    batch, wait = s.pace(MAX_BACKLOG_S + 0.05)
    assert batch is None and wait == pytest.approx(0.001)


def test_realtime_counts_late_commands_and_held_samples(v2):
    s = session(v2, mode='realtime')
    s.start(now=0.0)
    s.pace(0.0)
    assert len(s.pace(0.00101)[0]) == 5  # before any command: nothing held
    assert s.counters['held_samples'] == 0
    s.command([0.3, 0.0, 0.0, 0.0], now=0.00101)
    assert s.counters['late_commands'] == 1  # 5 samples stepped since the start
    batch, _ = s.pace(0.00201)  # the command applies from this burst on
    np.testing.assert_array_equal(batch.currents[:, 0], [0.3] * 5)
    assert s.counters['held_samples'] == 4  # the first sample used it, 4 held it
    s.command([0.1, 0.0, 0.0, 0.0], now=0.00201)
    assert s.counters['late_commands'] == 2  # more than one sample since the last one
    assert s.pace(0.0022)[0] is None  # not due yet
    s.command([0.2, 0.0, 0.0, 0.0], now=0.0022)  # no sample in between: not late
    assert s.counters['late_commands'] == 2
    batch, _ = s.pace(0.00301)
    np.testing.assert_array_equal(batch.currents[:, 0], [0.2] * 5)


def test_pause_and_resume_restart_pacing(v2):
    s = session(v2, mode='realtime')
    s.start(now=0.0)
    s.pace(0.0)
    s.set_paused(True, now=0.0)
    assert s.pace(5.0) == (None, PAUSED_POLL_S)
    s.set_paused(False, now=5.0)
    batch, wait = s.pace(5.0)  # pacing restarts now: no backlog, no overrun
    assert batch is None and wait == pytest.approx(0.001)
    assert len(s.pace(5.00101)[0]) == 5 and s.counters['overruns'] == 0


def test_crash_stops_the_run_and_reset_starts_a_new_one(v2):
    s = session(v2, mode='realtime', sim_kwargs={'magnet': 'free', 'x0': FALLING})
    first = s.start(now=0.0)
    s.pace(0.0)
    now, batches = 0.0, []
    while not s.crashed:
        now += 0.001
        batch, _ = s.pace(now)
        batches.append(batch)
        assert now < 1.0, 'the magnet never touched the base'
    last = batches[-1]
    assert last.crashed and s.counters['crashes'] == 1
    np.testing.assert_array_equal(s.last_state, s.sim.crash_state)
    stamps = np.concatenate([b.stamps_ns for b in batches])
    np.testing.assert_array_equal(np.diff(stamps), 200_000)
    assert stamps[-1] < s.sim.crash_time * 1e9
    assert s.pace(now + 1.0) == (None, PAUSED_POLL_S)  # integration stopped
    restart = s.reset(now=now)
    assert restart.indices.tolist() == [0] and s.counters['resets'] == 1
    assert restart.stamps_ns[0] == stamps[-1] + 200_000  # time goes on across runs
    np.testing.assert_array_equal(restart.readings, first.readings)
    np.testing.assert_array_equal(restart.states, first.states)


def test_reset_before_start_returns_nothing_and_start_returns_the_new_run(v2):
    s = session(v2, sim_kwargs={'x0': FALLING})
    s.sim.step(np.zeros(4))  # moved on: a reset goes back
    assert s.reset(now=0.0) is None and s.counters['resets'] == 1
    first = s.start(now=0.0)
    assert first.indices.tolist() == [0]
    np.testing.assert_array_equal(first.states[0], FALLING)


def test_coil_dynamics_and_real_time_factor(v2):
    sim = simulator(v2, coil=CoilDynamics.from_parameters(v2.params))
    s = SimulationSession(sim, 'realtime', now=0.0)
    s.start(now=0.0)
    s.command([1.0, 0.0, 0.0, 0.0], now=0.0)
    s.pace(0.0)
    batch, _ = s.pace(0.00101)
    assert 0 < batch.currents[-1, 0] < 1.0  # the coil lags the command
    assert s.measure_real_time_factor(0.002) == pytest.approx(6 * DT / 0.002)
    s.set_paused(True, now=0.002)
    assert s.measure_real_time_factor(1.0) == pytest.approx(6 * DT / 0.002)  # kept


def test_invalid_settings(v2):
    with pytest.raises(ValueError, match="mode must be one of realtime, lockstep, got 'fast'"):
        SimulationSession(simulator(v2), 'fast')
    with pytest.raises(ValueError, match='command_timeout must be a finite number > 0'):
        SimulationSession(simulator(v2), 'lockstep', command_timeout=0.0)


def test_tick_starts_lockstep_once_ready_then_holds_on_a_timeout(v2):
    s = session(v2, command_timeout=0.5)
    peers = []
    assert s.tick(0.0, lambda: bool(peers)) == (None, '', False)  # the graph is not there
    assert not s.started
    peers.append('controller')
    batch, note, warning = s.tick(0.1, lambda: bool(peers))
    assert batch.indices.tolist() == [0] and note == 'started: stepping in lockstep'
    assert not warning
    assert s.tick(0.5, lambda: 1 / 0) == (None, '', False)  # started: ready is not asked again
    batch, note, warning = s.tick(0.7, lambda: True)  # 0.6 s without a command
    assert batch.indices.tolist() == [1] and s.counters['timeouts'] == 1 and warning
    assert note == 'no command for 0.600 s > 0.5 s at t = 0.000200 s: holding the last command'
    s.set_paused(True, now=0.7)
    assert s.tick(10.0, lambda: True) == (None, '', False)  # paused: no timeout


def test_tick_in_real_time_waits_for_a_first_command_then_paces(v2):
    s = session(v2, mode='realtime')
    assert s.tick(0.0, lambda: True) == (None, '', False)  # ready, but no command yet
    s.command([0.1, 0.0, 0.0, 0.0], now=0.0)
    batch, note, _ = s.tick(0.0, lambda: True)
    assert batch.indices.tolist() == [0] and note == 'started: stepping in realtime'
    assert s.tick(0.0, lambda: True) == (None, '', False)  # pacing starts: a burst is not due yet
    batch = s.tick(0.00101, lambda: True).batch
    assert batch.indices.tolist() == [1, 2, 3, 4, 5]
    np.testing.assert_array_equal(batch.currents[:, 0], 0.1)  # the command held (ideal coils)


def test_command_lag_counts_the_samples_after_the_answered_one(v2):
    s = session(v2, mode='realtime')
    s.start(now=0.0)
    assert s.command_lag is None
    s.pace(0.0)
    s.pace(0.00101)  # samples 1..5 returned
    s.command(np.zeros(4), now=0.00101, stamp_ns=3 * 200_000)
    assert s.command_lag == 2
    s.command(np.zeros(4), now=0.00101)  # unstamped: the lag stays
    assert s.command_lag == 2


def test_realtime_averaged_samples_are_group_means_on_the_slower_grid(v2):
    s = SimulationSession(
        simulator(v2, sensor=SensorEffects(1e-4), magnet='free', seed=4), 'realtime', now=0.0,
        average=5,
    )  # fmt: skip
    reference = simulator(v2, sensor=SensorEffects(1e-4), magnet='free', seed=4)
    first = s.start(now=0.0)  # the run's sample 0 alone
    np.testing.assert_array_equal(first.readings[0], reference.reset())
    s.command([0.1, 0.0, 0.0, 0.0], now=0.0)
    assert s.pace(0.0)[0] is None  # the pacing's origin
    assert s.pace(0.0017)[0].indices.tolist() == [1]  # 8 steps: group 1-5, 6-8 wait
    batch, _ = s.pace(0.0027)  # 13 steps: group 6-10 completes, 11-13 wait
    assert batch.indices.tolist() == [2] and batch.stamps_ns.tolist() == [2_000_000]
    steps = [(reference.step([0.1, 0.0, 0.0, 0.0]), reference.currents, reference.state)
             for _ in range(10)]  # fmt: skip
    readings, currents, states = (np.array(c) for c in zip(*steps, strict=True))
    np.testing.assert_allclose(batch.readings[0], readings[5:].mean(axis=0))
    np.testing.assert_allclose(batch.currents[0], currents[5:].mean(axis=0))
    np.testing.assert_array_equal(batch.states[0], states[9])
    assert s.counters['samples'] == 14  # steps are counted


def test_averaged_samples_need_real_time(v2):
    with pytest.raises(ValueError, match='average 5 .* needs mode realtime'):
        SimulationSession(simulator(v2), 'lockstep', average=5)
    with pytest.raises(ValueError, match='samples per mean must be an integer >= 1'):
        SimulationSession(simulator(v2), 'realtime', average=0)
