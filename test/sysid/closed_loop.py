"""A simulated SISO feedback loop for closed-loop identification tests (independent of sysid).

Plant ``y0 = B/A u`` (output-error form), measured ``y = y0 + v`` with white
noise ``v``; controller ``u(t) = -K y(t) + r(t)`` with an external PRBS ``r``.
The noise reaches the input through the feedback, so ARX and IV with
input-based instruments are biased; ``r`` is a valid instrument.
"""

import numpy as np

from maglev_ros.sysid import IdData

A_CL = np.array([1.0, -1.5, 0.7])
B_CL = np.array([0.0, 0.5, 0.2])
THETA_CL = np.array([-1.5, 0.7, 0.5, 0.2])  # ARX 2 2 1 layout: a1 a2 b1 b2


def simulate_loop(N, seed, gain=0.5, noise=0.5, hold=1):
    """Return ``(data, r)``: the closed-loop data set and the excitation (N,).

    ``hold`` > 1 holds each random level that many samples (a slow, band-limited PRBS).
    """
    rng = np.random.default_rng(seed)
    r = np.repeat(rng.choice([-1.0, 1.0], -(-N // hold)), hold)[:N]
    v = noise * rng.standard_normal(N)
    y0 = np.zeros(N)
    y = np.zeros(N)
    u = np.zeros(N)
    for t in range(N):
        if t >= 2:
            y0[t] = -A_CL[1] * y0[t - 1] - A_CL[2] * y0[t - 2] + B_CL[1] * u[t - 1]
            y0[t] += B_CL[2] * u[t - 2]
        y[t] = y0[t] + v[t]
        u[t] = -gain * y[t] + r[t]
    return IdData(y, u, 1.0), r
