"""IV against the physics: closed-loop data of the simulated magnet, excitation as instruments."""

import numpy as np
import pytest

from maglev_ros.excitation.signals import prbs
from maglev_ros.sysid import IdData, arx, iv4
from maglev_ros.sysid.physics_check import compare_response, local_plant

from .lqg_loop import TS, run_loop

BAND = (20.0, 2000.0)  # Hz: compared band (see the test's docstring)


@pytest.fixture(scope='module')
def loop():
    # 25 000 samples (the lab's 5 s at 5 kHz) of a 0.2 A PRBS on the x pair
    return run_loop(prbs(25000, 0.2, seed=1))


def test_iv_with_the_excitation_recovers_the_linearisation(loop, capsys):
    """The seed's x model (7 9 1) by IV on the excitation is within 1 dB and 5 degrees.

    The band: the PRBS excites 0-2.5 kHz.  Below 20 Hz the x path has the
    unstable x mode (4.7 Hz) and the undamped tilt resonance (14.3 Hz); the
    loop holds the magnet there, and 5 s of data at 5 kHz do not pin a
    7 9 1 model down (deviations of 1-3 dB at 5-15 Hz for every estimator,
    also on noise-free data).  Over 20-2000 Hz, five noise/excitation seeds
    gave 0.23-0.91 dB and 1.1-3.7 deg for this IV, 0.67-0.90 dB and 2.3-3.9
    deg for direct ARX; this test runs the first seed.
    """
    drift = np.abs(loop.position - loop.linear.x_eq[:3]).max()
    assert drift < 0.5e-3  # the magnet stays within 0.5 mm during the excitation
    assert np.abs(loop.u).max() < 1.0  # A: within the coil drivers' limit
    ux = 0.5 * (loop.u[:, 0] - loop.u[:, 1])  # maglev-lab's u_x
    bx = loop.y[:, 0]  # x field of sensor 0
    data = IdData(bx - bx.mean(), ux - ux.mean(), TS, ['Bx_0'], ['u_x'])
    truth = local_plant(loop.linear, TS, 'Bx_0', 'x', delay_samples=1)
    iv = compare_response(iv4(data, 7, 9, 1, instruments=loop.r), truth, BAND)
    direct = compare_response(arx(data, 7, 9, 1), truth, BAND)
    input_iv = compare_response(iv4(data, 7, 9, 1), truth, BAND)
    with capsys.disabled():
        print(f'\nIV 7 9 1, excitation instruments: {iv.summary()}')
        print(f'IV 7 9 1, input instruments:      {input_iv.summary()}')
        print(f'ARX 7 9 1, direct:                {direct.summary()}')
        print(f'magnet within {drift * 1e3:.3f} mm, commands within {np.abs(loop.u).max():.2f} A')
    assert iv.within(1.0, 5.0), iv.summary()
