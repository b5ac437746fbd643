"""The lab session on any plant: settle, excite, record exactly N samples, stop."""

import numpy as np
import pytest

from maglev_ros.control.excitation import CommandExcitation, ExcitationSchedule
from maglev_ros.loop import (
    ControlLoop,
    LabSettings,
    OpenLoop,
    SampleBlock,
    SessionPlan,
    SimulatedPlant,
    build_lab_loop,
    lab_plan,
    run_session,
)
from maglev_ros.physics import Simulator, make_model

N = 300


def _settings(**more):
    e = CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs', seed=4, length=N)
    return LabSettings(samples=N, settle=0.05, seed=4, excitation=e, **more)


def test_lockstep_session_settles_excites_from_the_settle_sample_and_records_exactly_n():
    s = _settings()
    loop = build_lab_loop(s)
    plan = lab_plan(s)
    recorded, progress = [], []
    result = run_session(loop, plan, {'log': recorded.append}, lambda *a: progress.append(a))
    assert result.samples == N == len(recorded) and result.commands == N
    assert result.settled and not result.crashed and not result.stopped, result
    assert np.all(result.settle_rms < 1e-4)
    # the window: the samples after the settling's, consecutive, each with its command
    index = [w.sample.index for w in recorded]
    assert index == list(range(plan.settle_samples + 1, plan.settle_samples + 1 + N))
    assert all(w.command is not None for w in recorded)
    # the first recorded command carries the excitation's first row (computed at the
    # last settling sample, written one sample late), then row after row
    excitation = np.array([w.excitation for w in recorded])
    np.testing.assert_array_equal(excitation, ExcitationSchedule(s.excitation, 5000.0).sequence(N))
    assert result.positions.shape == (N, 3)
    assert progress[-1] == ('recording', N, N)


def test_open_loop_session_writes_exactly_the_excitation_on_a_fixed_magnet():
    sim = Simulator(make_model('maggy_v2'), 5000.0, magnet='fixed', seed=1)
    loop = ControlLoop(SimulatedPlant(sim), OpenLoop())
    ex = np.random.default_rng(0).uniform(-0.2, 0.2, (N + 1, 4))
    held = sim.state[:3].copy()
    plan = SessionPlan(N, 10, settle_window=5, set_point=held, excitation=ex)
    recorded = []
    result = run_session(loop, plan, {'log': recorded.append})
    assert result.samples == N and result.settled  # a fixed magnet does not move
    commands = np.array([w.command for w in recorded])
    np.testing.assert_array_equal(commands, ex[1 : N + 1])  # no command delay
    # the simulator drove its coils with them: the next sample's currents
    currents = np.array([w.sample.currents for w in recorded])
    np.testing.assert_allclose(currents[1:], commands[:-1], atol=1e-12)


def test_without_settling_the_recording_starts_with_the_first_sample():
    sim = Simulator(make_model('maggy_v2'), 5000.0, magnet='fixed', seed=1)
    ex = np.random.default_rng(0).uniform(-0.2, 0.2, (N, 4))
    loop = ControlLoop(SimulatedPlant(sim), OpenLoop(), excitation=ex)  # rows by sample
    recorded = []
    result = run_session(loop, SessionPlan(N, 0), {'log': recorded.append})
    assert result.samples == N == len(recorded) and result.commands == N
    assert [w.sample.index for w in recorded] == list(range(N))
    np.testing.assert_array_equal(np.array([w.command for w in recorded]), ex)
    assert result.recorded_s == pytest.approx((N - 1) / 5000.0)


class CountingPlant:
    """A lockstep plant of constant readings that can fail and records its close."""

    lockstep = True
    sample_rate = 1000.0
    n_inputs = 4

    def __init__(self, fail_at=None):
        self.k = 0
        self.fail_at = fail_at
        self.closed = 0
        self.written = []

    def read(self):
        if self.k == self.fail_at:
            e = np.empty(0)
            return SampleBlock(e.astype(np.int64), e, e.astype(np.int64), np.empty((0, 3)),
                               np.empty((0, 4)), e.astype(bool), crashed=True,
                               reason='the board link failed')  # fmt: skip
        k = np.array([self.k])
        return SampleBlock(k, k / 1000.0, k * 1_000_000, np.zeros((1, 3)), np.zeros((1, 4)),
                           np.ones(1, bool))  # fmt: skip

    def write(self, command, stamp_ns):
        self.written.append(np.array(command))
        self.k += 1

    def close(self):
        self.closed += 1


def test_a_stop_request_ends_the_session_and_closes_the_plant():
    plant = CountingPlant()
    loop = ControlLoop(plant, OpenLoop())
    plan = SessionPlan(samples=1000, settle_samples=10, position='estimate')
    seen = []
    result = run_session(loop, plan, {'log': seen.append}, stop=lambda: len(seen) >= 20)
    assert result.stopped and result.samples == 20 == len(seen)
    assert plant.closed == 1  # a board's close zeroes its coils
    assert np.isnan(result.settle_rms).all() and not result.settled  # no estimate


def test_a_failing_plant_ends_the_session_with_its_reason():
    plant = CountingPlant(fail_at=50)
    loop = ControlLoop(plant, OpenLoop())
    result = run_session(loop, SessionPlan(samples=100, settle_samples=10))
    assert result.crashed and result.reason == 'the board link failed'
    assert result.samples == 50 - 11 and plant.closed == 1


@pytest.mark.parametrize(
    'kwargs, match',
    [
        (dict(samples=0, settle_samples=1), 'samples must be an integer >= 1'),
        (dict(samples=10, settle_samples=-1), 'settle_samples must be an integer >= 0'),
        (dict(samples=10, settle_samples=1, position='truth'), "position must be 'state'"),
    ],
)
def test_a_bad_plan_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SessionPlan(**kwargs)
