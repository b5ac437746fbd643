"""The control loop on any plant: the order of its steps, the command delay, the excitation."""

import numpy as np
import pytest

from maglev_ros.control import ControllerConfig
from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.loop import ControlLoop, Plant, SampleBlock, SimulatedPlant


class RecordingPlant:
    """A lockstep plant whose reading at sample k is k, and which keeps what it is written."""

    lockstep = True
    sample_rate = 1000.0
    n_inputs = 4

    def __init__(self, samples=1000, invalid=()):
        self.k = 0
        self.samples = samples
        self.invalid = set(invalid)
        self.written = []

    def read(self):
        if self.k >= self.samples:
            e = np.empty(0)
            return SampleBlock(e, e, e, np.empty((0, 6)), np.empty((0, 4)), e, crashed=True,
                               reason='end of the recording')  # fmt: skip
        k = self.k
        return SampleBlock(
            np.array([k]), np.array([k / self.sample_rate]), np.array([k * 1_000_000]),
            np.full((1, 6), float(k)), np.zeros((1, 4)), np.array([k not in self.invalid]),
        )  # fmt: skip

    def write(self, command, stamp_ns):
        self.written.append((stamp_ns, np.array(command)))
        self.k += 1

    def close(self):
        pass


class EchoPd:
    """Answers sample k (its reading k) with k on every coil; inactive without input."""

    def __init__(self):
        self.calls = []
        self.active = True
        self.reference = None

    def reset(self):
        self.calls.clear()

    def command(self, t, y=None, currents=None):
        self.calls.append((t, None if y is None else float(y[0])))
        self.active = y is not None
        return np.full(4, float(y[0])) if y is not None else np.zeros(4)

    def status(self):
        from maglev_ros.control.safety import ControllerStatus

        return ControllerStatus('OK' if self.active else 'ERROR', 'no input', self.active, 0, 0)


def test_a_plant_is_read_estimated_controlled_and_written_in_order_through_the_delay():
    plant = RecordingPlant(samples=10)
    loop = ControlLoop(plant, EchoPd(), command_delay=2)
    assert loop.run(100) == 10 and loop.stopped and loop.reason == 'end of the recording'
    written = np.array([c[0] for _, c in plant.written])
    # the command answering sample k is written after sample k + 2; zeros before
    np.testing.assert_array_equal(written, [0, 0, *range(8)])
    assert [s for s, _ in plant.written] == [k * 1_000_000 for k in range(10)]


def test_the_excitation_is_added_while_the_controller_is_active_and_observers_see_its_part():
    plant = RecordingPlant(samples=6, invalid={3})
    excitation = np.full((4, 4), 0.5)  # samples 0-3 only
    seen = []
    loop = ControlLoop(plant, EchoPd(), excitation=excitation, observers=[seen.append])
    loop.run(6)
    applied = [float(c[0]) for _, c in plant.written]
    # 3 has no reading (inactive: no excitation), 4 and 5 are past the excitation
    assert applied == [0.5, 1.5, 2.5, 0.0, 4.0, 5.0]
    assert [s.valid for s in seen] == [True, True, True, False, True, True]
    assert [None if s.excitation is None else s.excitation[0] for s in seen] == [
        0.5, 0.5, 0.5, None, None, None,
    ]  # fmt: skip
    assert [s.command[0] for s in seen] == [0, 1, 2, 0, 4, 5]
    assert seen[3].level == 'ERROR' and seen[3].message == 'no input'


def test_observers_see_every_nth_sample():
    plant = RecordingPlant(samples=10)
    every, each = [], []
    ControlLoop(plant, EchoPd(), observers=[(every.append, 3), each.append]).run(10)
    assert [s.index for s in every] == [2, 5, 8]
    assert [s.index for s in each] == list(range(10))
    with pytest.raises(ValueError, match='every must be an integer >= 1, got 0'):
        ControlLoop(RecordingPlant(), EchoPd(), observers=[(each.append, 0)])


def test_the_lqr_needs_an_estimator_and_the_delay_is_checked():
    cl = make_closed_loop('maggy_v2')
    plant = SimulatedPlant(cl.simulator)
    with pytest.raises(ValueError, match='the LQR needs an estimator'):
        ControlLoop(plant, cl.controller)
    with pytest.raises(ValueError, match='command_delay must be an integer from 0 to 20, got 21'):
        ControlLoop(plant, cl.controller, cl.estimator, command_delay=21)


@pytest.mark.parametrize('mode', ['lqr', 'pd'])
def test_the_simulated_plant_levitates_in_the_loop_and_keeps_the_truth(mode):
    cl = make_closed_loop('maggy_v2', controller=ControllerConfig(mode=mode))
    plant = SimulatedPlant(cl.simulator)
    assert isinstance(plant, Plant)
    states = []
    loop = ControlLoop(plant, cl.controller, cl.estimator, command_delay=1,
                       observers=[lambda s: states.append(s.state)])  # fmt: skip
    assert loop.run(2500) == 2500 and not loop.stopped
    x = np.array(states)
    assert np.abs(x[1000:, :2]).max() < 0.5e-3  # x, y within 0.5 mm after 0.2 s
    assert cl.simulator.samples == 2500  # one step per command


def test_a_lost_magnet_stops_the_loop_with_the_reason():
    cl = make_closed_loop('maggy_v2')
    plant = SimulatedPlant(cl.simulator)
    plant.reset(np.r_[6e-3, 0, 0.04, np.zeros(9)])
    loop = ControlLoop(plant, cl.controller, cl.estimator, command_delay=1)
    done = loop.run(5000)
    assert loop.stopped and done < 5000
    assert loop.reason.endswith('s') and 'at t = ' in loop.reason
    assert plant.read().crashed and len(plant.read()) == 0
