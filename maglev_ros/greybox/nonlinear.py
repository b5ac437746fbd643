"""Nonlinear grey-box from levitation data: the full model's predictor (as ``nlgreyest``).

``nlgreyest`` simulates the full nonlinear model with the recorded inputs and
fits its outputs to the measured ones. The levitating magnet is open-loop
unstable, so a pure simulation driven by the recorded coil currents diverges
within tens of milliseconds. The predictor here is the nonlinear model in
innovation form, stabilised by the stationary Kalman gain ``K(theta)`` of its
own linearisation (:class:`~maglev_ros.greybox.LinearGreyBoxProblem`)::

    eps_k = y_{k+d} - h(xh_k, u_k; theta)                       (d: sensor delay)
    xh_{k+1} = Phi(xh_k, u_k -> u_{k+1}; theta) + K(theta) eps_k

``Phi`` integrates the full nonlinear 12-state model (fast field, true torque,
rigid kinematics: :func:`maglev_ros.physics.kernels.fast_dynamics`) over one
sample with RK4, the measured coil currents interpolated linearly between
samples (the coil electrics make the current move within a sample, time
constant L / R ~ 1.3 ms against 0.2 ms samples; a zero-order hold would bias
the force); ``h`` is the full sensor model (every source's field, sensor
position, rotation, gain and offset). ``xh_0`` is the hover state of
``theta``'s equilibrium; ``burn`` samples are left out while the start
transient dies out.

Unlike a simulation of the closed loop with the known controller, this needs
neither the controller nor the excitation: the inputs are the recorded
currents, whatever made them. The criterion and everything around it
(identifiability, standard deviations, validation, the parameter file) are
those of :func:`~maglev_ros.greybox.calibrate_dynamic`, which selects this form
with ``form='nonlinear'``. The whole predictor is one compiled (numba) loop;
the Jacobian is by central differences of it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..physics.kernels import fast_dynamics, fast_measurement
from ..physics.linearization import REDUCED_STATES
from ..physics.model import MaggyModel
from .errors import GreyBoxError
from .predictor import LinearGreyBoxProblem

__all__ = ['NonlinearGreyBoxProblem', 'DIVERGED', 'divergence_text']

#: Prediction error (T) given to every remaining sample once the predictor leaves
#: the workspace (the magnet more than 5 mm from where it started): a large,
#: finite residual that the solver steps back from.
DIVERGED = 1.0


@njit(cache=True, error_model='numpy')
def _predict(
    x0, u, y, delay, gain, rows, dt, substeps, src, coil, rim, par, sens, mag, work, out
):  # pragma: no cover - compiled
    """Nonlinear Kalman-gain predictor; fills ``out`` (N - delay, p) with eps_k."""
    n_x = x0.shape[0]
    m = u.shape[1]
    p = out.shape[1]
    last = u.shape[0] - 1
    x = x0.copy()
    ua = np.empty(m)
    um = np.empty(m)
    ub = np.empty(m)
    stage = np.empty(n_x)
    acc = np.empty(n_x)
    e = np.empty(p)
    h = dt / substeps
    for k in range(out.shape[0]):
        for j in range(m):
            ua[j] = u[k, j]
        yh = fast_measurement(x, ua, src, coil, sens, mag, work)
        for i in range(p):
            e[i] = y[k + delay, i] - yh[i]
            out[k, i] = e[i]
        nxt = k + 1 if k < last else k
        for s in range(substeps):
            f0 = s / substeps
            f1 = (s + 0.5) / substeps
            f2 = (s + 1.0) / substeps
            for j in range(m):
                du = u[nxt, j] - u[k, j]
                ua[j] = u[k, j] + f0 * du
                um[j] = u[k, j] + f1 * du
                ub[j] = u[k, j] + f2 * du
            r = fast_dynamics(x, ua, src, coil, rim, par, work)
            for i in range(n_x):
                acc[i] = r[i]
                stage[i] = x[i] + 0.5 * h * r[i]
            r = fast_dynamics(stage, um, src, coil, rim, par, work)
            for i in range(n_x):
                acc[i] += 2.0 * r[i]
                stage[i] = x[i] + 0.5 * h * r[i]
            r = fast_dynamics(stage, um, src, coil, rim, par, work)
            for i in range(n_x):
                acc[i] += 2.0 * r[i]
                stage[i] = x[i] + h * r[i]
            r = fast_dynamics(stage, ub, src, coil, rim, par, work)
            for i in range(n_x):
                x[i] += (h / 6.0) * (acc[i] + r[i])
        for a in range(rows.shape[0]):
            s = 0.0
            for i in range(p):
                s += gain[a, i] * e[i]
            x[rows[a]] += s
        bad = False
        for i in range(n_x):
            if not np.isfinite(x[i]):
                bad = True
        for i in range(3):
            if abs(x[i] - x0[i]) > 5e-3:
                bad = True
        if bad:
            for kk in range(k + 1, out.shape[0]):
                for i in range(p):
                    out[kk, i] = DIVERGED
            return k + 1
    return out.shape[0]


def divergence_text(problem: NonlinearGreyBoxProblem) -> str:
    """Describe the predictor's divergences so far ('' if none).

    Parameters
    ----------
    problem : NonlinearGreyBoxProblem
        A problem whose residuals have been evaluated.

    Returns
    -------
    str
        Count, first record, sample and time, and whether it was in the burn-in.
    """
    if not problem.divergences:
        return ''
    name, k, t = problem.divergences[0]
    where = 'in the burn-in, ' if k <= problem.burn else ''
    return (
        f'the nonlinear predictor diverged in {problem.diverged} of '
        f'{problem.evaluations} evaluations (first: {name}, sample {k}, '
        f't = {t:.4g} s, {where}the predicted magnet moved more than 5 mm from its equilibrium)'
    )


class NonlinearGreyBoxProblem(LinearGreyBoxProblem):
    """The nonlinear grey-box prediction-error problem (same interface as the linear one).

    Parameters
    ----------
    vector : ParameterVector
        Parameters (the free ones are estimated).
    experiments : sequence of LevitationExperiment
        Estimation data (same sample time and sensors).
    delay : int
        Sensor delay, samples.
    sigma : ndarray, shape (3 k,)
        Noise level per channel, T rms (weights and the Kalman filter's R).
    process_noise : float
        Input-disturbance level ``q`` of the Kalman gain that stabilises the
        predictor, A rms.
    burn : int
        Samples of each record left out of the criterion while the
        predictor's initial error dies out.
    substeps : int
        RK4 steps per sample.
    """

    def __init__(
        self,
        vector,
        experiments,
        delay: int,
        sigma: np.ndarray,
        process_noise: float = 1e-3,
        burn: int = 100,
        substeps: int = 1,
    ):
        super().__init__(vector, experiments, delay, sigma, process_noise, burn)
        if self.measurement != 'raw':
            raise GreyBoxError(
                'the nonlinear form models the raw field only: use --form linear with '
                '--measurement board'
            )
        self.substeps = int(substeps)
        self.diverged = 0
        #: (record name, sample, time in s) of the first divergence of each evaluation
        self.divergences: list[tuple[str, int, float]] = []

    def errors(self, values: dict[str, float]) -> list[np.ndarray]:
        """Prediction errors of the nonlinear predictor per experiment (burn-in left out), T.

        Parameters
        ----------
        values : dict
            Parameter values by name, SI.

        Raises
        ------
        GreyBoxError
            The parameter set has no equilibrium (the magnet cannot levitate).
        """
        system = self.system(values)
        model = MaggyModel(self.vector.apply(values))
        src, coil, rim, par, work = model.fast_arguments()
        _, _, sens, mag, _ = model.measurement_arguments()
        sens = np.ascontiguousarray(sens[self._sensor_rows()])
        x0 = np.ascontiguousarray(model.hover_state(system.z_eq))
        rows = np.asarray(REDUCED_STATES, dtype=np.int64)
        out = []
        for e in self.experiments:
            eps = np.empty((e.samples - self.delay, self.channels.size))
            done = _predict(
                x0,
                e.u,
                e.y,
                self.delay,
                system.K,
                rows,
                self.Ts,
                self.substeps,
                src,
                coil,
                rim,
                par,
                sens,
                mag,
                work,
                eps,
            )
            if done < eps.shape[0]:
                self.diverged += 1
                self.divergences.append((e.name, int(done), float((done - 1) * self.Ts)))
            out.append(eps[self.burn :])
        return out

    def _sensor_rows(self) -> np.ndarray:
        """Sensors of the parameter set that the records hold (in channel order)."""
        if self.channels.size % 3:
            raise GreyBoxError('field channels must come in whole sensors')
        return self.channels[::3] // 3
