"""A minimal LQG loop around the nonlinear V2 simulator, for closed-loop identification tests.

Stand-in for the estimator and controller of the closed-loop issue (a
steady-state Kalman filter and a python-control ``dlqr`` gain on the sampled
linearisation, with the sensor's sample of delay as states), written here so
that the identification test does not depend on their tuning.  The excitation
is added to the controller's command on the x pair (x+ = r, x- = -r), as an
input disturbance: the feedback then also carries the sensor noise into the
input, which is what biases direct ARX.
"""

from dataclasses import dataclass

import control
import numpy as np
from scipy.linalg import expm

from maglev_ros.physics import SensorEffects, Simulator, linearize, make_model

TS = 2e-4  # s, the board's 5 kHz
NOISE = 1e-4  # T rms per axis (the board's Hall sensors: 0.06-0.11 mT)
LSB = 0.098e-3  # T per LSB


@dataclass(frozen=True)
class LoopRun:
    y: np.ndarray  # (N, 3k) sensor readings, T
    u: np.ndarray  # (N, 4) total commands (feedback + excitation), A
    r: np.ndarray  # (N,) excitation on the x pair, A
    position: np.ndarray  # (N, 3) true magnet position, m
    linear: object  # the reduced linearisation


def run_loop(excitation, settle=2000, seed=3, r_weight=100.0, w_velocity=1e-10):
    """Levitate V2 (noise, quantisation, 1 sample delay), settle, then add ``excitation``.

    Returns the ``len(excitation)`` samples after settling; sample ``t`` pairs the
    reading at ``t`` with the command applied over ``[t, t + 1)``.  The default
    weights (input weight ``r_weight`` against 1e8 per m^2 of position, velocity
    disturbance variance ``w_velocity``) keep the commands within the coils'
    1 A (feedback about 0.17 A rms per coil with the 0.1 mT sensor noise).
    """
    model = make_model('maggy_v2')
    lin = linearize(model).reduced()
    A, B, C, D = lin.A, lin.B, lin.C, lin.D
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    E = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * TS)
    # xi = [x(t), u(t-1), x(t-1), u(t-2)]: the reading at t is C x(t-1) + D u(t-2)
    size = 2 * (n + m)
    F, G = np.zeros((size, size)), np.zeros((size, m))
    F[:n, :n], G[:n] = E[:n, :n], E[:n, n:]
    G[n : n + m] = np.eye(m)
    F[n + m : 2 * n + m, :n] = np.eye(n)
    F[2 * n + m :, n : n + m] = np.eye(m)
    H = np.zeros((p, size))
    H[:, n + m : 2 * n + m], H[:, 2 * n + m :] = C, D
    Q = np.zeros((size, size))
    Q[:n, :n] = np.diag([1e8] * 3 + [1e2] * 7)  # positions in m weigh most
    K = control.dlqr(F, G, Q, r_weight * np.eye(m))[0]
    W = np.zeros((size, size))
    W[:n, :n] = 1e-12 * np.eye(n)
    W[5:n, 5:n] = w_velocity * np.eye(n - 5)  # velocity disturbances
    L = control.dlqe(F, np.eye(size), H, W, (NOISE**2 + LSB**2 / 12) * np.eye(p))[0]
    sensor = SensorEffects(noise_rms=NOISE, quantization=LSB, delay_samples=1)
    sim = Simulator(model, 1 / TS, sensor=sensor, seed=seed)
    reading = sim.reset()
    xi = np.zeros(size)
    total = settle + len(excitation)
    ys, us, xs = np.empty((total, p)), np.empty((total, m)), np.empty((total, 3))
    r = np.r_[np.zeros(settle), excitation]
    for t in range(total):
        xi = xi + L @ (reading - lin.y_eq - H @ xi)  # correct with the reading at t
        u = -K @ xi + r[t] * np.array([1.0, -1.0, 0.0, 0.0])
        ys[t], us[t], xs[t] = reading, u, sim.state[:3]
        reading = sim.step(u)
        if sim.crashed:
            raise RuntimeError(f'the magnet fell at sample {t}: {sim.reason}')
        xi = F @ xi + G @ u  # predict with the applied command
    keep = slice(settle, total)
    return LoopRun(ys[keep], us[keep], r[keep], xs[keep], lin)
