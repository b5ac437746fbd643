"""filterpy's KF, EKF and UKF run as our estimators run: the reference they are checked against.

The same sample handling as :class:`~maglev_ros.estimation.Estimator` (the
delayed reading, its currents, the prediction's trapezoidal hold, the
published estimate) with filterpy's ``KalmanFilter``,
``ExtendedKalmanFilter`` and ``UnscentedKalmanFilter`` doing the filtering,
on the *full* nonlinear model of the physics core: one RK4 step of
``physics.kernels.rk4_sample`` per sample (per sigma point) and
``physics.kernels.fast_measurement`` for h; the EKF's Jacobians by central
differences every sample (``kernels.ekf_transition``, ``kernels.ekf_measure``).
No gate, no freeze check (filterpy has neither): a whole sample with a NaN is
a predict-only step.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import (
    ExtendedKalmanFilter,
    KalmanFilter,
    MerweScaledSigmaPoints,
    UnscentedKalmanFilter,
)

from ..physics import kernels as phys
from ..physics.linearization import FD_STEP
from .kernels import ekf_measure, ekf_transition, embed_state
from .nonlinear import compiled_arguments

__all__ = ['FilterpyReference']


class FilterpyReference:
    """filterpy's filter of the same kind as ``estimator``, stepped sample by sample.

    Parameters
    ----------
    estimator : Estimator
        The estimator to mirror (its kind, model, Q, R, initial covariance,
        sensor delay).

    Attributes
    ----------
    filter : filterpy filter
        ``KalmanFilter``, ``ExtendedKalmanFilter`` or ``UnscentedKalmanFilter``.
    """

    def __init__(self, estimator):
        self.est = est = estimator
        self.kind = est.config.filter
        self.delayed = est.config.sensor_delay == 1
        n, m = est.n_states, est.n_outputs
        self._x_eq = np.ascontiguousarray(est.x_eq)
        self._reduced = est.reduced
        self._f_args, self._h_args = compiled_arguments(est.model)
        if self.kind == 'kf':
            kf = KalmanFilter(dim_x=n, dim_z=m, dim_u=est.n_inputs)
            kf.F, kf.B, kf.H = est.F.copy(), est.B.copy(), est.H.copy()
            self.filter = kf
        elif self.kind == 'ekf':
            ekf = ExtendedKalmanFilter(dim_x=n, dim_z=m, dim_u=est.n_inputs)
            ekf.predict_x = self._ekf_mean
            self.filter = ekf
        else:
            points = MerweScaledSigmaPoints(n, alpha=1.0, beta=2.0, kappa=0.0)
            self.filter = UnscentedKalmanFilter(
                dim_x=n, dim_z=m, dt=est.dt, hx=self.hx, fx=self.fx, points=points
            )
        self.filter.Q = est.Q.copy()
        self.filter.R = np.diag(est.r_diag)
        self.reset()

    def reset(self) -> None:
        """Start at the equilibrium with the estimator's initial covariance."""
        f = self.filter
        f.x = np.zeros(self.est.n_states)
        f.P = self.est.initial_covariance()
        if self.kind == 'ukf':
            f.sigmas_f = f.points_fn.sigma_points(f.x, f.P)
        self._prev = None
        self._mean = None

    # the full model
    def fx(self, s, dt, u):
        """Return the filter state ``s`` (reduced + biases) one RK4 step on, currents ``u``.

        Parameters
        ----------
        s : ndarray, shape (n,)
            Filter state: reduced deviation from the equilibrium, then the biases.
        dt : float
            Step, s.
        u : ndarray, shape (n_s,)
            Coil currents held over the step, A.
        """
        nr = self._reduced.shape[0]
        x12 = embed_state(np.ascontiguousarray(s[:nr]), self._x_eq, self._reduced)
        new = phys.rk4_sample(x12, u, dt, 1, phys.COIL_IDEAL, np.ones(3), *self._f_args)
        out = s.copy()
        out[:nr] = (new - self._x_eq)[self._reduced]
        return out

    def hx(self, s, u):
        """Return the readings of the filter state ``s`` with currents ``u`` (+ biases), T.

        Parameters
        ----------
        s : ndarray, shape (n,)
            Filter state: reduced deviation from the equilibrium, then (optionally)
            one bias per reading, T.
        u : ndarray, shape (n_s,)
            Coil currents, A.
        """
        nr = self._reduced.shape[0]
        x12 = embed_state(np.ascontiguousarray(s[:nr]), self._x_eq, self._reduced)
        y = phys.fast_measurement(x12, u, *self._h_args)
        return y + s[nr:] if s.shape[0] > nr else y

    def _ekf_mean(self, u=0):
        self.filter.x = self._mean  # filterpy's predict_x sets x

    def step(self, y, currents) -> tuple[np.ndarray, np.ndarray]:
        """One sample; return the published estimate (reduced + biases) and its covariance.

        Parameters
        ----------
        y : ndarray, shape (3 k,)
            Readings, T (any NaN: no update).
        currents : ndarray, shape (n_s,)
            Measured currents, A.
        """
        f, est = self.filter, self.est
        currents = np.ascontiguousarray(currents, dtype=float)
        held = currents if not self.delayed or self._prev is None else self._prev
        across = 0.5 * (held + currents) if self.delayed else currents
        self._prev = currents
        z = None if not np.all(np.isfinite(y)) else np.asarray(y, dtype=float)
        if self.kind == 'kf':
            f.update(None if z is None else est.measurement(z, held))
        elif self.kind == 'ekf':
            if z is not None:
                h, jac = ekf_measure(f.x, held, self._x_eq, self._reduced, FD_STEP, *self._h_args)
                f.update(z, lambda x, jac=jac: jac, lambda x, h=h: h)
        elif z is not None:
            f.update(z, u=held)
        if not self.delayed:
            published = f.x.copy(), f.P.copy()
        if self.kind == 'kf':
            f.predict(u=across - est.u_eq)
        elif self.kind == 'ekf':
            self._mean, f.F = ekf_transition(
                f.x, across, self._x_eq, self._reduced, est.dt, FD_STEP, *self._f_args
            )
            f.predict()
        else:
            f.predict(u=across)
        if self.delayed:
            published = f.x.copy(), f.P.copy()
        return published
