"""Why model mismatch loses the magnet: the linearised closed loop's slowest oscillation.

The loop of issue 9 (KF + LQR, one sample of sensor delay, command one sample
late, coil L/R lag) is linear near the equilibrium, so its stability under a
parameter error is an eigenvalue problem: the *plant* is the linearisation of
the mismatched model (polarisation and mass scaled; the inertia is not: the
tests scale the mass only), the KF is the believed model's with its
steady-state gain (``scipy.linalg.solve_discrete_are``), the LQR the
believed model's gain, wired with the exact timing of
:class:`maglev_ros.control.closed_loop.ClosedLoop` (update at k-1 with the
reading of k-1, predict to k holding the mean of the currents of k-1 and k,
command from k applied over k+1 -> k+2). Printed per case: the decay rate
(1/s; positive = growing) and frequency of the closed loop's slowest
oscillatory mode, for each ``angular_acceleration_noise`` given.

With a trusted tilt model (0.5 rad/s^2) the KF leaves the tilt modes nearly
undamped (V2: poles at -0.19 +- 89.8j 1/s, the open-loop tilt oscillation at
14.3 Hz) and the nominal loop's slowest oscillation decays at only 0.1/s; a
10 % weaker tilt mode (polarisation x0.9, inertia unchanged) makes it grow.

Usage::

    python benchmarks/mismatch_margins.py                       # 0.5 and 50 rad/s^2
    python benchmarks/mismatch_margins.py --noise 0.5 5 20 50 --no-bias
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from scipy.linalg import solve_discrete_are

from maglev_ros.control import ControllerConfig, make_controller
from maglev_ros.estimation import EstimatorConfig, make_estimator
from maglev_ros.physics import linearize, load_parameters, make_model
from maglev_ros.physics.discretization import zoh

CASES = ((1.0, 1.0), (1.1, 1.1), (0.9, 0.9), (1.1, 0.9), (0.9, 1.1))


def plant_model(name: str, polarization: float, mass: float, believed):
    """Return the mismatched plant model (polarisation and mass scaled)."""
    p = load_parameters(name)
    magnet = dataclasses.replace(
        p.magnet, polarization=p.magnet.polarization * polarization, mass=p.magnet.mass * mass
    )
    return make_model(p.replace(magnet=magnet, solenoid_radius_correction=believed.correction))


def loop_matrix(plant_linear, plant_params, estimator, controller) -> np.ndarray:
    """Closed-loop transition matrix, state [p(k-1), p(k), x_prior(k-1), c(k-1)].

    ``p = [dx (10), i (4)]`` is the plant's deviation and coil currents.
    """
    nr, m = 10, estimator.n_inputs
    coils = plant_params.coils
    tau = coils.inductance / coils.resistance
    ac = np.zeros((nr + m, nr + m))
    ac[:nr, :nr] = plant_linear.A
    ac[:nr, nr:] = plant_linear.B
    ac[nr:, nr:] = -np.eye(m) / tau
    bc = np.zeros((nr + m, m))
    bc[nr:] = np.eye(m) / tau
    dt = 1.0 / controller.config.sample_rate
    phi, gam = zoh(ac, bc, dt)
    cp = np.hstack([plant_linear.C, plant_linear.D])
    F, B, H, D, Q = estimator.F, estimator.B, estimator.H, estimator.D, estimator.Q
    R = np.diag(estimator.r_diag)
    P = solve_discrete_are(F.T, H.T, Q, R)  # prior covariance
    L = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    d = controller.design
    kx, ki, kc = (d.K[:, d.layout[k]] for k in ('dx', 'i', 'c_prev'))
    n_p, n = nr + m, F.shape[0]

    def step(s):
        pp, pc = s[:n_p], s[n_p : 2 * n_p]
        xb, c_prev = s[2 * n_p : 2 * n_p + n], s[2 * n_p + n :]
        z = cp @ pp - D @ pp[nr:]
        xu = xb + L @ (z - H @ xb)
        xk = F @ xu + B @ (0.5 * (pp[nr:] + pc[nr:]))
        c = -kx @ xk[:nr] - ki @ pc[nr:] - kc @ c_prev
        return np.concatenate([pc, phi @ pc + gam @ c_prev, xk, c])

    size = 2 * n_p + n + m
    return np.column_stack([step(v) for v in np.eye(size)])


def slowest_oscillation(matrix: np.ndarray, rate: float) -> tuple[float, float]:
    """Decay rate (1/s, positive: growing) and frequency (Hz) of the slowest oscillation."""
    ev = np.linalg.eigvals(matrix)
    ev = ev[np.abs(ev) > 1e-12]  # the pure delays' zero eigenvalues
    s = np.log(ev.astype(complex)) * rate
    osc = s[np.abs(s.imag) / (2 * np.pi) > 1.0]
    worst = osc[np.argmax(osc.real)]
    return float(worst.real), float(abs(worst.imag) / (2 * np.pi))


def main(argv=None) -> int:
    """Print the slowest closed-loop oscillation per set, mismatch case and tilt noise."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--params', nargs='+', default=['maggy_v2', 'maggy_v4'])
    parser.add_argument('--noise', nargs='+', type=float, default=[0.5, 50.0])
    parser.add_argument('--no-bias', action='store_true', help='without the bias states')
    args = parser.parse_args(argv)
    controller_config = ControllerConfig()
    for name in args.params:
        believed = make_model(name)
        lin = linearize(believed)
        controller = make_controller(believed, controller_config, linear=lin)
        for fj, fm in CASES:
            plant = plant_model(name, fj, fm, believed)
            plin = linearize(plant).reduced()
            cells = []
            for noise in args.noise:
                config = EstimatorConfig(
                    bias_states=not args.no_bias, angular_acceleration_noise=noise
                )
                est = make_estimator(believed, config, linear=lin)
                rate, freq = slowest_oscillation(
                    loop_matrix(plin, plant.params, est, controller),
                    controller_config.sample_rate,
                )
                cells.append(f'noise {noise:g}: {rate:+7.2f}/s at {freq:5.1f} Hz')
            print(f'{name} J x{fj} m x{fm}: ' + ' | '.join(cells), flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
