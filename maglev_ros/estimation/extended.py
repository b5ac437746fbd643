"""Extended Kalman filter on the nonlinear model (the physics core's f and h)."""

from __future__ import annotations

import numpy as np

from ..physics.linearization import FD_STEP
from .base import Estimator
from .filter_model import measurement_jacobian
from .nonlinear import FilterModel, require_fast_field
from .nonlinear_kernels import ekf_predict_fast, ekf_predict_full, ekf_step, ekf_update

__all__ = ['ExtendedEstimator']


class ExtendedEstimator(Estimator):
    """EKF on the reduced deviation ``dx`` with the fast model's compiled f and h.

    Update: h(x, i) itself (so the coils' direct field enters exactly) and
    its Jacobian by central differences, gated per sensor, Joseph form.
    Prediction with the measured currents held over the sample, by
    :attr:`EstimatorConfig.prediction`:

    ``fast`` (default)
        one exponential-Euler step ``x + dt phi1(A dt) f(x)`` and ``F =
        exp(A dt)`` (series), with the Jacobian A of f refreshed one column
        per sample (forward differences): two evaluations of f per sample.
    ``full``
        one RK4 step of f, A by central differences every sample (24
        evaluations of f): the reference the fast one is measured against.

    A whole sample is one compiled call (:func:`nonlinear_kernels.ekf_step`).
    Process noise as the KF's (fixed, from the equilibrium's discretised
    input matrices). Fast field model only.

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
            self.filter_model = FilterModel(self.model)
            self.Q = np.ascontiguousarray(self.discrete_process_noise())
            self._x_eq = np.ascontiguousarray(self.x_eq)
            self._fast = self.config.prediction == 'fast'
            fm = self.filter_model
            self._f_args = fm.fast_f_args if self._fast else fm.f_args
            self._A = np.zeros((self.n_reduced, self.n_reduced))
            self._cursor = np.zeros(1, dtype=np.int64)
            self._no_currents = np.full(self.n_inputs, np.nan)
        self._x = np.ascontiguousarray(dx, dtype=float)
        self._P = np.ascontiguousarray(P, dtype=float)
        self._cursor[0] = -1  # the whole Jacobian at the next prediction

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
        return measurement_jacobian(
            self._x,
            np.ascontiguousarray(currents, dtype=float),
            self._x_eq,
            self.reduced,
            FD_STEP,
            *self.filter_model.h_args,
        )

    def _update(self, y, currents, available):
        x, P, accepted, nis_sensor, nis, dof = ekf_update(
            self._x,
            self._P,
            np.ascontiguousarray(y, dtype=float),
            np.ascontiguousarray(currents, dtype=float),
            available,
            self.r_diag,
            self.gate,
            self._x_eq,
            self.reduced,
            FD_STEP,
            *self.filter_model.h_args,
        )
        self._x, self._P = x, P
        return accepted, nis_sensor, nis, dof

    def _predict(self, currents) -> None:
        u = np.ascontiguousarray(currents, dtype=float)
        f_args = self._f_args
        if self._fast:
            self._x, self._P = ekf_predict_fast(
                self._x,
                self._P,
                u,
                self.Q,
                self._A,
                self._cursor,
                self._x_eq,
                self.reduced,
                self.dt,
                FD_STEP,
                *f_args,
            )
        else:
            self._x, self._P = ekf_predict_full(
                self._x, self._P, u, self.Q, self._x_eq, self.reduced, self.dt, FD_STEP, *f_args
            )

    def step(self, y, currents) -> np.ndarray:
        """Process one complete sample and return the state estimate.

        As :meth:`Estimator.step`, in one compiled call
        (:func:`nonlinear_kernels.ekf_step`: the same operations, so the same
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
        nis, dof = ekf_step(
            y,
            currents,
            prev,
            self.config.sensor_delay == 1,
            self._fast,
            self._x,
            self._P,
            self.Q,
            self._A,
            self._cursor,
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
            FD_STEP,
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
