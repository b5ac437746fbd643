"""Extended Kalman filter on the nonlinear model (the physics core's f and h)."""

from __future__ import annotations

import numpy as np

from ..physics.linearization import FD_STEP
from .base import Estimator
from .kernels import ekf_measure, ekf_predict, gated_update
from .nonlinear import compiled_arguments, require_fast_field

__all__ = ['ExtendedEstimator']


class ExtendedEstimator(Estimator):
    """EKF on the reduced deviation ``dx`` with the fast model's compiled f and h.

    Prediction: one RK4 step of f with the measured currents held over the
    sample; covariance through the transition matrix of the local Jacobian
    (central differences of f in one compiled call). Update: h(x, i) itself
    (so the coils' direct field enters exactly) and its Jacobian, gated per
    sensor, Joseph form. Process noise as the KF's (fixed, from the
    equilibrium's discretised input matrices). Fast field model only.

    Parameters
    ----------
    model, config, linear
        As :class:`Estimator`.
    """

    def __init__(self, model, config=None, linear=None):
        require_fast_field(model, 'EKF')
        self._x = None
        super().__init__(model, config, linear)

    def _set_state(self, dx, P) -> None:
        if self._x is None:
            self._f_args, self._h_args = compiled_arguments(self.model)
            self.Q = np.ascontiguousarray(self.discrete_process_noise())
            self._x_eq = np.ascontiguousarray(self.x_eq)
        self._x = np.ascontiguousarray(dx, dtype=float)
        self._P = np.ascontiguousarray(P, dtype=float)

    @property
    def deviation(self) -> np.ndarray:
        """Filter state: reduced deviation (+ biases), shape (n,)."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """Filter covariance, shape (n, n)."""
        return self._P.copy()

    def predicted_reading(self, currents) -> tuple[np.ndarray, np.ndarray]:
        """H at the current state and its Jacobian: (3 k,), (3 k, n).

        Parameters
        ----------
        currents : array_like, shape (n_s,)
            Coil currents, A.
        """
        return ekf_measure(
            self._x,
            np.ascontiguousarray(currents, dtype=float),
            self._x_eq,
            self.reduced,
            FD_STEP,
            *self._h_args,
        )

    def _update(self, y, currents, available):
        h, H = self.predicted_reading(currents)
        nu = y - h
        nu = np.where(np.isfinite(nu), nu, 0.0)
        x, P, accepted, nis_sensor, nis, dof = gated_update(
            self._x, self._P, H, self.r_diag, nu, available, self.gate
        )
        self._x, self._P = x, P
        return accepted, nis_sensor, nis, dof

    def _predict(self, currents) -> None:
        self._x, self._P = ekf_predict(
            self._x,
            self._P,
            np.ascontiguousarray(currents, dtype=float),
            self.Q,
            self._x_eq,
            self.reduced,
            self.dt,
            FD_STEP,
            *self._f_args,
        )
