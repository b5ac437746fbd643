"""Unscented Kalman filter through filterpy's ``UnscentedKalmanFilter``."""

from __future__ import annotations

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter, unscented_transform

from ..physics import kernels as phys
from .base import Estimator
from .kernels import embed_state
from .nonlinear import compiled_arguments, require_fast_field

__all__ = ['UnscentedEstimator']


class UnscentedEstimator(Estimator):
    """UKF on the reduced deviation ``dx``: filterpy's predict and update, our f and h.

    Sigma points: Merwe's scaled set with alpha = 1, beta = 2, kappa = 0 (all
    weights of the mean non-negative, points at sqrt(n) standard deviations).
    f: one compiled RK4 step of the fast model with the measured currents held;
    h: the compiled sensor model (coils' direct field included) plus the bias
    states if any. The chi-square gate per sensor uses the unscented
    transform of the prior sigma points through h (filterpy's
    ``unscented_transform``); the accepted sensors' rows then go to filterpy's
    ``update``. P is symmetrised after each update (filterpy's UKF update is
    ``P - K S K'``, not Joseph). Fast field model only.

    Parameters
    ----------
    model, config, linear
        As :class:`Estimator`.
    """

    def __init__(self, model, config=None, linear=None):
        require_fast_field(model, 'UKF')
        self.ukf = None
        super().__init__(model, config, linear)

    def _set_state(self, dx, P) -> None:
        if self.ukf is None:
            self._f_args, self._h_args = compiled_arguments(self.model)
            self._x_eq = np.ascontiguousarray(self.x_eq)
            self._electrical = np.ones(3)
            points = MerweScaledSigmaPoints(self.n_states, alpha=1.0, beta=2.0, kappa=0.0)
            self.ukf = UnscentedKalmanFilter(
                dim_x=self.n_states,
                dim_z=self.n_outputs,
                dt=self.dt,
                hx=self._hx,
                fx=self._fx,
                points=points,
            )
            self.ukf.Q = self.discrete_process_noise()
            self.ukf.R = np.diag(self.r_diag)
        self.ukf.x = np.array(dx, dtype=float)
        self.ukf.P = np.array(P, dtype=float)
        self.ukf.sigmas_f = self.ukf.points_fn.sigma_points(self.ukf.x, self.ukf.P)

    def _fx(self, s, dt, u):
        nr = self.n_reduced
        x12 = embed_state(np.ascontiguousarray(s[:nr]), self._x_eq, self.reduced)
        new = phys.rk4_sample(x12, u, dt, 1, phys.COIL_IDEAL, self._electrical, *self._f_args)
        out = s.copy()
        out[:nr] = (new - self._x_eq)[self.reduced]
        return out

    def _hx(self, s, u, rows=None):
        nr = self.n_reduced
        x12 = embed_state(np.ascontiguousarray(s[:nr]), self._x_eq, self.reduced)
        y = phys.fast_measurement(x12, u, *self._h_args)
        if s.shape[0] > nr:
            y = y + s[nr:]
        return y if rows is None else y[rows]

    @property
    def deviation(self) -> np.ndarray:
        """Filter state: reduced deviation (+ biases), shape (n,)."""
        return self.ukf.x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """Filter covariance, shape (n, n)."""
        return self.ukf.P.copy()

    def _update(self, y, currents, available):
        u = np.ascontiguousarray(currents, dtype=float)
        ukf = self.ukf
        sigmas_h = np.array([self._hx(s, u) for s in ukf.sigmas_f])
        zp, S = unscented_transform(sigmas_h, ukf.Wm, ukf.Wc, ukf.R)
        nu = y - zp
        accepted = np.zeros(self.n_sensors, dtype=bool)
        nis_sensor = np.full(self.n_sensors, np.nan)
        for k in np.flatnonzero(available):
            block = slice(3 * k, 3 * k + 3)
            value = float(nu[block] @ np.linalg.solve(S[block, block], nu[block]))
            nis_sensor[k] = value
            accepted[k] = value <= self.gate
        if not accepted.any():
            return accepted, nis_sensor, 0.0, 0
        rows = np.flatnonzero(np.repeat(accepted, 3))
        nis = float(nu[rows] @ np.linalg.solve(S[np.ix_(rows, rows)], nu[rows]))
        ukf.update(y[rows], R=ukf.R[np.ix_(rows, rows)], u=u, rows=rows)
        ukf.P = 0.5 * (ukf.P + ukf.P.T)
        return accepted, nis_sensor, nis, rows.size

    def _predict(self, currents) -> None:
        self.ukf.predict(u=np.ascontiguousarray(currents, dtype=float))
