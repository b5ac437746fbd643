"""A closed loop around the open-loop-unstable Maggy V4 plant, from the physics package.

The lateral x subsystem (states x, beta, vx, wy) of the V4 linearisation is
open-loop unstable (a real pole near +54.5 1/s). It is sampled at 200 Hz (zero-order
hold), stabilised by a discrete LQR acting on a Kalman filter's estimate from the
measured field ``Bx`` of sensor 0 (so the sensor noise reaches the input, as on a
real board), disturbed by a force noise and measured with white sensor noise. An optional
external excitation ``r`` (random levels) is added to the controller's current.
Used by the closed-loop identification tests; independent of the sysid code.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import linalg

from maglev_ros.physics import MaggyModel, load_parameters
from maglev_ros.physics.discretization import zoh
from maglev_ros.physics.linearization import linearize
from maglev_ros.sysid import IdData

TS = 0.005  # s (200 Hz, as the V4 board's PC-control stream)
STATES = (0, 4, 5, 9)  # x, beta, vx, wy of the reduced linearisation
SENSOR_NOISE = 5e-6  # T rms
FORCE_NOISE = 0.02  # A rms, equivalent current disturbance


@lru_cache(maxsize=1)
def plant() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Discrete x subsystem ``(Ad, Bd (4, 1), C (1, 4), unstable pole in 1/s)``."""
    lin = linearize(MaggyModel(load_parameters('maggy_v4'))).reduced()
    idx = np.array(STATES)
    A = lin.A[np.ix_(idx, idx)]
    B = (lin.B[idx, 0] - lin.B[idx, 1])[:, None] / 2  # ux: +ux on x+, -ux on x-
    C = lin.C[0:1, idx]
    pole = float(np.max(np.linalg.eigvals(A).real))
    Ad, Bd = zoh(A, B, TS)
    return Ad, Bd, C, pole


def simulate(
    N: int, seed: int, excitation: float = 0.0, hold: int = 3
) -> tuple[IdData, np.ndarray]:
    """Return ``(data, r)``: closed-loop data (Bx_0 in T, ux in A) and the excitation (N,).

    ``excitation`` is the amplitude in A of random levels held ``hold`` samples
    (0: no excitation, the loop runs on its noise alone).
    """
    Ad, Bd, C, _ = plant()
    Q = np.diag([1e6, 1e2, 1e2, 1e-1])
    P = linalg.solve_discrete_are(Ad, Bd, Q, np.eye(1))
    K = np.linalg.solve(np.eye(1) + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
    W = FORCE_NOISE**2 * (Bd @ Bd.T) + 1e-12 * np.eye(4)
    S = linalg.solve_discrete_are(Ad.T, C.T, W, np.eye(1) * SENSOR_NOISE**2)
    L = S @ C.T / (C @ S @ C.T + SENSOR_NOISE**2)  # (4, 1) filter gain
    rng = np.random.default_rng(seed)
    r = excitation * np.repeat(rng.uniform(-1, 1, -(-N // hold)), hold)[:N]
    w = FORCE_NOISE * rng.standard_normal(N)
    v = SENSOR_NOISE * rng.standard_normal(N)
    x = np.zeros(4)
    xp = np.zeros(4)  # the filter's prediction of x(t) from data up to t - 1
    y = np.zeros(N)
    u = np.zeros(N)
    for t in range(N):
        y[t] = (C @ x)[0] + v[t]
        xf = xp + L[:, 0] * (y[t] - (C @ xp)[0])
        u[t] = -(K @ xf)[0] + r[t]
        x = Ad @ x + Bd[:, 0] * (u[t] + w[t])
        xp = Ad @ xf + Bd[:, 0] * u[t]
    data = IdData(y, u, TS, ['Bx_0'], ['ux'], ['T'], ['A'])
    return data, r
