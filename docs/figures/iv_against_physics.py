# ruff: noqa: E402, E501, B905 - a figure script: sys.path set before the test import
"""Regenerate docs/figures/iv_against_physics.png (run from the repository root).

    .venv/bin/python docs/figures/iv_against_physics.py

The closed loop of test/sysid/test_iv_physics.py, the three estimates of the
x model against the sampled linearisation (about 1 minute).
"""

import sys
import warnings

warnings.simplefilter('ignore')
sys.path.insert(0, 'test')
import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt
from sysid.test_iv_physics import (
    AMPLITUDE,
    BAND,
    CLOCK,
    SAMPLES,
    SETTLE,
    ExcitedController,
    RecordingSimulator,
)

from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.excitation.signals import prbs
from maglev_ros.physics import linearize, make_model
from maglev_ros.sysid import IdData, arx, iv4
from maglev_ros.sysid.physics_check import compare_response, local_plant

loop = make_closed_loop('maggy_v2', seed=0)
sim = RecordingSimulator(loop.simulator)
loop.simulator = sim
r = np.r_[np.zeros(SETTLE), prbs(SAMPLES, AMPLITUDE, (0.0, CLOCK), seed=0)]
loop.controller = ExcitedController(loop.controller, np.outer(r, [1, -1, 0, 0]), sim.dt)
res = loop.run((SETTLE + SAMPLES) * sim.dt)
keep = slice(SETTLE, SETTLE + SAMPLES)
y = np.array(sim.readings[: SETTLE + SAMPLES])[keep]
cmd = res.command[keep]
r = r[keep]
ux = 0.5 * (cmd[:, 0] - cmd[:, 1])
bx = y[:, 0]
data = IdData(bx - bx.mean(), ux - ux.mean(), sim.dt)
truth = local_plant(
    linearize(make_model('maggy_v2')).reduced(),
    sim.dt,
    'Bx_0',
    'x',
    2,
    sim.coil.inductance / sim.coil.resistance,
)
models = {
    'IV 7 9 1, excitation instruments': iv4(data, 7, 9, 1, instruments=r),
    'IV4 7 9 1, input instruments': iv4(data, 7, 9, 1),
    'ARX 7 9 1, direct': arx(data, 7, 9, 1),
}
f = np.geomspace(2, 1000, 1500)
g0 = truth.freqresp(f)
fig, ax = plt.subplots(3, 1, figsize=(8, 9.5), sharex=True)
ax[0].semilogx(
    f,
    20 * np.log10(np.abs(g0) * 1e3),
    'k',
    lw=2.5,
    label='linearisation (ZOH, coil L/R, 2 samples delay)',
)
ax[1].semilogx(f, np.degrees(np.unwrap(np.angle(g0))), 'k', lw=2.5)
for (name, m), c in zip(models.items(), ['C0', 'C3', 'C2']):
    g = m.freqresp(f)[:, 0, 0]
    dev = compare_response(m, truth, BAND)
    print(name, dev.summary())
    ax[0].semilogx(
        f,
        20 * np.log10(np.abs(g) * 1e3),
        c,
        label=f'{name}: max {dev.max_db:.2f} dB / {dev.max_deg:.1f}°',
    )
    ax[1].semilogx(f, np.degrees(np.unwrap(np.angle(g))), c)
    ax[2].semilogx(dev.frequencies, dev.gain_db, c, label=f'{name}, dB')
    ax[2].semilogx(dev.frequencies, dev.phase_deg / 5, c + '--', label=f'{name}, deg / 5')
for a in ax:
    a.axvspan(*BAND, color='0.92', zorder=-1)
    a.grid(True, which='both', alpha=0.3)
ax[2].axhline(1, color='k', ls=':')
ax[2].axhline(-1, color='k', ls=':')
ax[0].set_ylim(-20, 5)
ax[0].set_ylabel('|Bx_0 / u_x|  (dB re 1 mT/A)')
ax[1].set_ylabel('phase (deg)')
ax[2].set_ylabel('deviation from physics\n(dB; deg/5; dotted: the 1 dB / 5 deg bound)')
ax[2].set_xlabel('frequency (Hz)')
ax[0].legend(fontsize=7.5, loc='lower left')
ax[2].legend(fontsize=6.5, ncol=2, loc='lower left')
ax[2].set_ylim(-3, 3)
ax[0].set_title(
    'V2 closed loop (KF + LQR), 25 000 samples, 0.1 A PRBS added to the command on u_x\nidentified vs linearisation; grey: compared band 10-300 Hz (14.3 Hz undamped tilt resonance left out)',
    fontsize=9,
)
fig.tight_layout()
fig.savefig('docs/figures/iv_against_physics.png', dpi=110)
