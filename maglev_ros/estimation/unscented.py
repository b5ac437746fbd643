"""Unscented Kalman filter: filterpy's ``UnscentedKalmanFilter`` equations, compiled."""

from __future__ import annotations

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints

from ..physics.linearization import FD_STEP
from .base import Estimator
from .nonlinear import FilterModel, require_fast_field
from .nonlinear_kernels import sigma_points, ukf_predict, ukf_step, ukf_update

__all__ = ['UnscentedEstimator']


class UnscentedEstimator(Estimator):
    """UKF on the reduced deviation ``dx``, filterpy's equations in compiled kernels.

    Sigma points: Merwe's scaled set with alpha = 1, beta = 2, kappa = 0 (all
    weights of the mean non-negative, points at sqrt(n) standard deviations;
    filterpy's ``MerweScaledSigmaPoints`` gives the weights). f: the
    prediction :attr:`EstimatorConfig.prediction` names, per sigma point
    (``fast``: one exponential-Euler step, the Jacobian from the sigma points'
    statistical linearisation, the magnetic wrench from the centre's and its
    Jacobian in the pose, one column refreshed a sample; ``full``: one RK4
    step); h: the sensor model
    (coils' direct field included) plus the bias states if any. The
    chi-square gate per sensor uses the unscented transform of the predicted
    sigma points through h; the accepted sensors' rows then update as
    filterpy's ``update`` does (``P - K S K'``, not Joseph: the UKF has no H),
    P symmetrised after. A whole sample is one compiled call
    (:func:`nonlinear_kernels.ukf_step`). Fast field model only.

    Parameters
    ----------
    model, config, linear
        As :class:`Estimator`.
    """

    def __init__(self, model, config=None, linear=None):
        require_fast_field(model, 'UKF')
        self._x = None
        super().__init__(model, config, linear)

    def _set_state(self, dx, P) -> None:
        if self._x is None:
            self.filter_model = FilterModel(self.model)
            self._x_eq = np.ascontiguousarray(self.x_eq)
            self.points = MerweScaledSigmaPoints(self.n_states, alpha=1.0, beta=2.0, kappa=0.0)
            self.Wm = np.ascontiguousarray(self.points.Wm, dtype=float)
            self.Wc = np.ascontiguousarray(self.points.Wc, dtype=float)
            self._lambda = float(self.points.alpha**2 * (self.n_states + self.points.kappa))
            self._lambda -= self.n_states
            self.Q = np.ascontiguousarray(self.discrete_process_noise())
            self._fast = self.config.prediction == 'fast'
            fm = self.filter_model
            self._f_args = fm.fast_f_args if self._fast else fm.f_args
            self._no_currents = np.full(self.n_inputs, np.nan)
            n_pose = int(np.sum(self.reduced < 6))  # x y z alpha beta
            self._J = np.zeros((6, n_pose))  # the wrench's Jacobian in the pose
            self._cursor = np.zeros(1, dtype=np.int64)
        self._x = np.ascontiguousarray(dx, dtype=float)
        self._P = np.ascontiguousarray(P, dtype=float)
        self._sigmas, _ = sigma_points(self._x, self._P, self._lambda)
        self._cursor[0] = -1  # the whole wrench Jacobian at the next prediction

    @property
    def deviation(self) -> np.ndarray:
        """Filter state: reduced deviation (+ biases), shape (n,)."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """Filter covariance, shape (n, n)."""
        return self._P.copy()

    def _update(self, y, currents, available):
        x, P, accepted, nis_sensor, nis, dof = ukf_update(
            self._x,
            self._P,
            self._sigmas,
            np.ascontiguousarray(y, dtype=float),
            np.ascontiguousarray(currents, dtype=float),
            available,
            self.r_diag,
            self.gate,
            self.Wm,
            self.Wc,
            self._x_eq,
            self.reduced,
            *self.filter_model.h_args,
        )
        self._x, self._P = x, P
        return accepted, nis_sensor, nis, dof

    def _predict(self, currents) -> None:
        self._x, self._P, self._sigmas = ukf_predict(
            self._x,
            self._P,
            np.ascontiguousarray(currents, dtype=float),
            self.Q,
            self.Wm,
            self.Wc,
            self._lambda,
            self._fast,
            self._J,
            self._cursor,
            FD_STEP,
            self._x_eq,
            self.reduced,
            self.dt,
            *self._f_args,
        )

    def step(self, y, currents) -> np.ndarray:
        """Process one complete sample and return the state estimate.

        As :meth:`Estimator.step`, in one compiled call
        (:func:`nonlinear_kernels.ukf_step`: the same operations, so the same
        numbers).

        Parameters
        ----------
        y : array_like, shape (3 k,)
            The sample's sensor readings, T (NaN for a missing sensor).
        currents : array_like, shape (n_s,)
            The sample's measured coil currents, A.

        Returns
        -------
        ndarray, shape (12,)
            Estimated state at this sample (gamma and wz are 0: unobservable).
        """
        y, currents = self._checked_sample(y, currents)
        prev = self._no_currents if self._prev_currents is None else self._prev_currents
        f = self.freeze
        out_x = np.empty(12)
        accepted = np.empty(self.n_sensors, dtype=bool)
        nis_sensor = np.empty(self.n_sensors)
        nis, dof = ukf_step(
            y,
            currents,
            prev,
            self.config.sensor_delay == 1,
            self._fast,
            self._J,
            self._cursor,
            FD_STEP,
            self._x,
            self._P,
            self._sigmas,
            self.Q,
            self.Wm,
            self.Wc,
            self._lambda,
            self.r_diag,
            self.gate,
            f._last,
            f.runs,
            f.run,
            f.frozen,
            f.events,
            self.missing,
            self.rejected,
            self._x_eq,
            self.reduced,
            self.dt,
            *self._f_args,
            *self.filter_model.h_args[:-1],
            out_x,
            self._out_p,
            accepted,
            nis_sensor,
        )
        self._out_x = out_x
        self._record(currents, accepted, nis_sensor, nis, dof)
        return self._out_x
