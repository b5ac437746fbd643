"""The online identifier observer: the recursive ARX of the bag converter's pairing."""

import numpy as np

from maglev_ros.loop import LoopSample, OnlineIdentifier, WindowSample
from maglev_ros.sysid import IdData, arx


def _sample(k, reading, currents):
    return LoopSample(k, k * 2e-4, k * 200_000, reading, currents, True, None, None, None,
                      0.0, 0, None, None, None, None, 'OK', '')  # fmt: skip


def test_held_commands_are_the_inputs_and_the_estimate_is_the_batch_arx():
    rng = np.random.default_rng(3)
    n = 1500
    commands = rng.uniform(-0.5, 0.5, (n // 5, 4)).repeat(5, axis=0)  # one a burst of 5
    u = 0.5 * (commands[:, 0] - commands[:, 1])
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.8 * u[t - 1] + 0.01 * rng.standard_normal()
    ident = OnlineIdentifier(outputs=[0], inputs=[[0.5, -0.5, 0, 0]], na=2, nb=1, nk=1,
                             batch=64, names=(('y',), ('u',)))  # fmt: skip
    for t in range(n):
        command = commands[t] if t % 5 == 4 or t == 0 else None  # the burst's last answers
        ident(WindowSample(_sample(t, np.array([y[t], 0, 0]), np.zeros(4)), command, None))
    # the inputs the identifier held: the command of the last answered sample
    held = np.where((np.arange(n) % 5 == 4) | (np.arange(n) == 0), 1, 0)
    last = np.maximum.accumulate(np.where(held, np.arange(n), 0))
    u_held = u[last]
    online = ident.estimate(2e-4)
    batch = arx(IdData(y, u_held, 2e-4, ['y'], ['u']), 2, 1, 1)
    assert online.samples == n
    np.testing.assert_allclose(online.model.theta, batch.theta, rtol=1e-6, atol=1e-9)


def test_a_board_is_identified_against_the_currents_it_reports():
    rng = np.random.default_rng(4)
    n = 800
    currents = rng.uniform(-1, 1, (n, 4))
    ux = 0.5 * (currents[:, 0] - currents[:, 1])
    y = np.r_[0.0, 0.3 * ux[:-1]]
    ident = OnlineIdentifier(outputs=[0], inputs=[[0.5, -0.5, 0, 0]], source='currents',
                             na=1, nb=1, nk=1)  # fmt: skip
    for t in range(n):
        ident(WindowSample(_sample(t, np.array([y[t], 0, 0]), currents[t]), None, None))
    online = ident.estimate(2e-4)
    np.testing.assert_allclose(online.model.theta, [0.0, 0.3], atol=1e-6)
    assert OnlineIdentifier().estimate(2e-4) is None  # no sample: nothing to report
