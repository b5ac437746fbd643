"""IV against the physics: the closed loop of the simulated magnet, the excitation as instruments.

The ROS-free closed loop (:mod:`maglev_ros.control.closed_loop`: simulator ->
KF -> LQR, V2, sensor noise 0.1 mT and quantisation 0.098 mT, one sample of
sensor delay, coil dynamics, the command taking effect one sample late) with
a PRBS added to the controller's command on the x pair (x+ = r, x- = -r), as
an input disturbance.  The loop's objects are used as they are; two thin
wrappers record the sensor readings and add the excitation.
"""

import numpy as np
import pytest

from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.excitation.signals import prbs
from maglev_ros.physics import linearize, make_model
from maglev_ros.sysid import IdData, arx, iv4
from maglev_ros.sysid.physics_check import compare_response, local_plant

SETTLE, SAMPLES = 2000, 25000  # the lab's 5 s at 5 kHz, after 0.4 s of settling
AMPLITUDE = 0.1  # A: with the LQR's 1 A limit the coils stay within their ~1.1 A
CLOCK = 0.2  # PRBS band (0, 0.2) of Nyquist: a new level every 5 samples, power below ~500 Hz
BAND = (10.0, 300.0)  # Hz, see test_iv_with_the_excitation_recovers_the_linearisation


class RecordingSimulator:
    """The loop's simulator, keeping every reading it returns."""

    def __init__(self, simulator):
        self._simulator = simulator
        self.readings = []

    def __getattr__(self, name):
        return getattr(self._simulator, name)

    def reset(self, x0=None):
        reading = self._simulator.reset(x0)
        self.readings = [reading]
        return reading

    def step(self, u):
        reading = self._simulator.step(u)
        self.readings.append(reading)
        return reading


class ExcitedController:
    """The loop's controller with ``excitation[k]`` added to its command of sample k."""

    def __init__(self, controller, excitation, dt):
        self._controller = controller
        self.excitation = excitation
        self.dt = dt

    def __getattr__(self, name):
        return getattr(self._controller, name)

    def command(self, t, *args):
        return self._controller.command(t, *args) + self.excitation[int(round(t / self.dt))]


@pytest.fixture(scope='module')
def closed_loop_run():
    loop = make_closed_loop('maggy_v2', seed=0)
    simulator = RecordingSimulator(loop.simulator)
    loop.simulator = simulator
    r = np.r_[np.zeros(SETTLE), prbs(SAMPLES, AMPLITUDE, (0.0, CLOCK), seed=0)]
    loop.controller = ExcitedController(loop.controller, np.outer(r, [1, -1, 0, 0]), simulator.dt)
    result = loop.run((SETTLE + SAMPLES) * simulator.dt)
    assert not result.crashed, result.reason
    keep = slice(SETTLE, SETTLE + SAMPLES)
    readings = np.array(simulator.readings[: SETTLE + SAMPLES])[keep]
    return result, readings, result.command[keep], r[keep], simulator


def test_iv_with_the_excitation_recovers_the_linearisation(closed_loop_run, capsys):
    """The seed's x model (7 9 1) by IV on the excitation: within 1 dB and 5 degrees.

    Truth: the linearisation sampled with the loop's timing - coil L/R lag,
    the command one sample late and the sensor one sample late
    (``delay_samples=2``).  Band: the PRBS's power lies below ~500 Hz and the
    coils (L/R = 1.3 ms) filter it above ~120 Hz; 10-300 Hz is compared,
    without +-1 Hz around the undamped 14.3 Hz tilt resonance.  (Below 10 Hz
    the unstable x mode and the loop holding the magnet leave a 7 9 1 model
    at 5 kHz undetermined for any estimator, noise-free data included.)
    Two seeds gave 0.29 dB / 2.4 deg and 0.28 dB / 3.0 deg for this IV; direct
    ARX 1.0-1.2 dB / 7 deg, input-based IV4 4-5 dB / 7-21 deg.
    """
    result, readings, command, r, simulator = closed_loop_run
    excursion = np.abs(result.position_error()[SETTLE:]).max()
    assert excursion < 0.5e-3  # the magnet stays within 0.5 mm during the excitation
    assert np.abs(command).max() <= 1.1 + 1e-9  # A: the LQR's 1 A plus 0.1 A, the drivers' limit
    ux = 0.5 * (command[:, 0] - command[:, 1])  # maglev-lab's u_x (total command)
    bx = readings[:, 0]  # x field of sensor 0
    data = IdData(bx - bx.mean(), ux - ux.mean(), simulator.dt, ['Bx_0'], ['u_x'])
    coil = simulator.coil
    truth = local_plant(
        linearize(make_model('maggy_v2')).reduced(),  # the plant's own model
        simulator.dt,
        'Bx_0',
        'x',
        delay_samples=2,
        coil_time_constant=coil.inductance / coil.resistance,
    )
    iv = compare_response(iv4(data, 7, 9, 1, instruments=r), truth, BAND)
    direct = compare_response(arx(data, 7, 9, 1), truth, BAND)
    input_iv = compare_response(iv4(data, 7, 9, 1), truth, BAND)
    with capsys.disabled():
        print(f'\nIV 7 9 1, excitation instruments: {iv.summary()}')
        print(f'IV4 7 9 1, input instruments:     {input_iv.summary()}')
        print(f'ARX 7 9 1, direct:                {direct.summary()}')
        print(
            f'magnet within {excursion * 1e3:.3f} mm of its set-point, '
            f'commands within {np.abs(command).max():.2f} A'
        )
    assert iv.excluded and 14.0 < iv.excluded[0] < 14.6
    assert iv.within(1.0, 5.0), iv.summary()
