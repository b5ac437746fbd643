"""Linear Kalman filter on the reduced 10-state model about the equilibrium."""

from __future__ import annotations

import math

import numpy as np

from ..physics.discretization import zoh
from .base import Estimator
from .kernels import gated_update, kf_predict, kf_sample, kf_step, kf_steps

__all__ = ['KalmanEstimator']


class KalmanEstimator(Estimator):
    """KF on ``dx = x - x_eq`` (10 reduced states, optional 9 sensor-bias states).

    Model, discretised exactly (ZOH) at the sample rate::

        dx(k+1) = Ad dx(k) + Bd (i(k) - u_eq)
        y(k)    = y_eq + C dx(k) + D (i(k) - u_eq) [+ b]     (D: the coils' direct field)

    The readings enter as ``z = y - y_eq - D (i - u_eq)``, so the update is the
    plain ``z = H x`` form of filterpy's ``KalmanFilter`` (H = C, or [C I] with
    bias states) and the two agree to round-off on the same data.

    With ``magnet_strength`` a state ``s`` scales the magnet's own field,
    ``y = y_eq + (1 + s) (g + C dx) - g + D (i - u_eq)`` with ``g`` the
    magnet's field at the sensors at the equilibrium (the base magnets' and
    the coils' field do not depend on the magnet). Each update uses this
    model's Jacobian at the prior, ``[(1 + s) C, g + C dx]`` (an extended
    update of that one bilinear term; the prediction stays linear). Process
    noise: ``Q = Gd diag(s^2) Gd'`` with ``Gd`` the ZOH input matrix of the coil
    currents and of unit accelerations (see :meth:`Estimator.disturbance_matrix`).

    Parameters
    ----------
    model, config, linear
        As :class:`Estimator`.
    """

    def __init__(self, model, config=None, linear=None):
        self._x = None
        self._P = None
        self._no_currents = np.full(model.n_inputs, np.nan)  # kf_step: no previous sample
        super().__init__(model, config, linear)

    def _build(self) -> None:
        lin = self.linear
        n, nr = self.n_states, self.n_reduced
        g = self.disturbance_matrix()
        ad, gd = zoh(lin.A, g, self.dt)  # g's first columns are B: gd's are Bd
        F = np.eye(n)
        F[:nr, :nr] = ad
        B = np.zeros((n, self.n_inputs))
        B[:nr] = gd[:, : self.n_inputs]
        H = np.zeros((self.n_outputs, n))
        H[:, :nr] = lin.C
        if self.filter_start > self.bias_start:
            H[:, self.bias_start : self.filter_start] = np.eye(self.n_outputs)
        self.C = np.ascontiguousarray(lin.C, dtype=float)
        self.magnet_field = self.y_eq - self.model.measurement(
            self.x_eq, self.u_eq, with_magnet=False
        )
        if self.strength_index is not None:
            H[:, self.strength_index] = self.magnet_field
        D = np.array(lin.D, dtype=float)
        Q = self.process_noise(gd)
        if self.board is not None:
            D = self._board_model(F, B, H, D, Q, gd)
        self.F = np.ascontiguousarray(F)
        self.B = np.ascontiguousarray(B)
        self.H = np.ascontiguousarray(H)
        self.D = np.ascontiguousarray(D)
        self.Q = np.ascontiguousarray(0.5 * (Q + Q.T))

    def _board_model(self, F, B, H, D, Q, gd) -> np.ndarray:
        """Make F, B, H, Q (in place) and D, y_eq model the board's processed field.

        The readings are ``b = raw - baseline - feedthrough i`` (the physics
        model's own baseline and feedthrough: :class:`BoardProcessing`); each
        filtered channel reads its filter state ``f``, which the board updates
        at each of its 200 us steps inside the host sample:
        ``f+ = a f + Fx dx + Fw w`` (:meth:`BoardProcessing.host_filter`, with
        the currents and the disturbances held over the sample, in deviations
        from the equilibrium). The filter's process noise is that of the
        disturbances through ``Fw`` (correlated with the magnet's).

        Returns
        -------
        ndarray, shape (p, n_s)
            The processed D (zero on filtered rows: they read the filter state).
        """
        board, nr, m = self.board, self.n_reduced, self.n_inputs
        rows = np.flatnonzero(board.filtered)
        cols = np.arange(self.filter_start, self.n_states)
        self.y_eq = self.y_eq - board.baseline - board.feedthrough @ self.u_eq
        d = D - board.feedthrough
        g = self.disturbance_matrix()
        d_all = np.zeros((rows.size, g.shape[1]))
        d_all[:, :m] = d[rows]
        fx, fw, a = board.host_filter(self.linear.A, g, self.C[rows], d_all, self.dt)
        self.filter_pole = a
        F[cols] = 0.0
        F[np.ix_(cols, np.arange(nr))] = fx
        F[np.ix_(cols, cols)] = a * np.eye(rows.size)
        B[cols] = fw[:, :m]
        H[np.ix_(rows, np.arange(nr))] = 0.0  # a bias still adds after the filter
        H[np.ix_(rows, cols)] = np.eye(rows.size)
        d[rows] = 0.0
        full_g = np.zeros((self.n_states, g.shape[1]))
        full_g[:nr] = gd
        full_g[cols] = fw
        full = (full_g * self.disturbance_std() ** 2) @ full_g.T
        Q[:, cols] = full[:, cols]
        Q[cols, :] = full[cols, :]
        return d

    def _set_state(self, dx, P) -> None:
        if self._x is None:
            self._build()
            self._p_init = np.ascontiguousarray(self.initial_covariance())
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

    def measurement(self, y, currents) -> np.ndarray:
        """``z = y - y_eq - D (i - u_eq)``: the reading as the linear filter sees it, T.

        Parameters
        ----------
        y : array_like, shape (3 k,)
            Readings, T.
        currents : array_like, shape (m,)
            Currents at the reading's instant, A.
        """
        return y - self.y_eq - self.D @ (currents - self.u_eq)

    def _linearize_strength(self) -> np.ndarray:
        """Set H to the strength model's Jacobian at the prior; return its y_eq term, T.

        The kernel's residual ``y - y_eq' - D du - H x`` then equals
        ``y - h(x)`` of the bilinear model: ``y_eq' = y_eq - s C dx``.
        """
        if self.strength_index is None:
            return self.y_eq
        nr, j = self.n_reduced, self.strength_index
        s = self._x[j]
        cdx = self.C @ self._x[:nr]
        self.H[:, :nr] = (1.0 + s) * self.C
        self.H[:, j] = self.magnet_field + cdx
        return self.y_eq - s * cdx

    @property
    def strength(self) -> float:
        """Estimated magnet strength ``s`` (relative; 0 without the state)."""
        return 0.0 if self.strength_index is None else float(self._x[self.strength_index])

    def _update(self, y, currents, available):
        y_eq = self._linearize_strength()
        z = y - y_eq - self.D @ (currents - self.u_eq)
        nu = z - self.H @ self._x
        nu = np.where(np.isfinite(nu), nu, 0.0)
        x, P, accepted, nis_sensor, nis, dof = gated_update(
            self._x, self._P, self.H, self.r_diag, nu, available, self.gate
        )
        self._x, self._P = x, P
        return accepted, nis_sensor, nis, dof

    def step(self, y, currents) -> np.ndarray:
        """Process one complete sample and return the state estimate.

        As :meth:`Estimator.step`; without the magnet-strength state the whole
        sample is one compiled call (:func:`kernels.kf_step`: the same
        operations, so the same numbers), ~3x less time per sample, what a
        5 kHz estimator in real time needs.

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
        if self.strength_index is not None:
            return super().step(y, currents)
        # C-contiguous always: one compiled signature (a strided row, e.g. of a
        # burst's array, would compile kf_step again: seconds in a real-time loop)
        y = np.ascontiguousarray(y, dtype=float)
        currents = np.ascontiguousarray(currents, dtype=float)
        if y.shape != (self.n_outputs,):
            raise ValueError(f'y must have {self.n_outputs} readings, got shape {y.shape}')
        if currents.shape != (self.n_inputs,) or not math.isfinite(currents.sum()):
            raise ValueError(f'currents must be {self.n_inputs} finite numbers, got {currents!r}')
        out_x = np.empty(12)
        self._x, self._P, self._out_p, accepted, nis_sensor, nis, dof = kf_step(
            y, currents, self._previous_currents(), *self._kernel_args(), out_x
        )
        self._out_x = out_x
        self._record(currents, accepted, nis_sensor, nis, dof)
        return self._out_x  # the prior's x_eq if the filter restarted

    def step_many(self, ys, currents) -> tuple[np.ndarray, np.ndarray]:
        """Process n complete samples in order, as n calls of :meth:`step`, in one call.

        Without the magnet-strength state, one compiled call for them all
        (:func:`kernels.kf_steps`, the same numbers as :meth:`step`): a burst of
        a real-time simulator in the same process (the estimator node's
        ``intra_process``) at ~13 us a sample.

        Parameters
        ----------
        ys : array_like, shape (n, 3 k)
            Readings, T (NaN for a missing sensor).
        currents : array_like, shape (n, n_s)
            Measured coil currents, A.

        Returns
        -------
        x : ndarray, shape (n, 12)
            The estimate of each sample.
        p : ndarray, shape (n, n_states, n_states)
            Its covariance (:attr:`state_covariance`).
        """
        if self.strength_index is not None:
            return super().step_many(ys, currents)
        ys, currents = self._checked_many(ys, currents)
        n = ys.shape[0]
        x = np.empty((n, 12))
        p = np.empty((n, self.n_states, self.n_states))
        if n == 0:
            return x, p
        counters = np.array([self.samples, self.unaccepted, self.restarts], dtype=np.int64)
        self._x, self._P, accepted, nis_sensor, nis, dof = kf_steps(
            ys,
            currents,
            self._previous_currents(),
            *self._kernel_args(),
            self._nis_ring,
            self._dof_ring,
            counters,
            self.config.lost_samples,
            self._p_init,
            x,
            p,
        )
        self.samples, self.unaccepted, self.restarts = (int(v) for v in counters)
        self.last_nis, self.last_dof = nis, dof
        self.last_accepted, self.last_nis_sensor = accepted, nis_sensor
        self._prev_currents = currents[-1].copy()
        self._out_x = x[-1].copy()
        self._out_p = p[-1].copy()
        return x, p

    def _previous_currents(self) -> np.ndarray:
        """Return the last sample's currents for the kernels (NaN before the first), A."""
        if self._prev_currents is None:
            return self._no_currents
        return np.ascontiguousarray(self._prev_currents, dtype=float)

    def _kernel_args(self) -> tuple:
        """Arguments of kf_step and kf_steps after the currents: model, gate, counts."""
        f = self.freeze
        return (
            self.config.sensor_delay == 1,
            self._x,
            self._P,
            self.F,
            self.B,
            self.H,
            self.D,
            self.y_eq,
            self.u_eq,
            self.r_diag,
            self.Q,
            self.gate,
            f._last,
            f.runs,
            f.run,
            f.frozen,
            f.events,
            self.missing,
            self.rejected,
            self.x_eq,
            self.reduced,
        )

    def _sample(self, y, held, across, available, delayed):
        """Run the whole sample in one compiled call (:func:`kernels.kf_sample`)."""
        y_eq = self._linearize_strength()
        x_out, p_out, self._x, self._P, accepted, nis_sensor, nis, dof = kf_sample(
            self._x,
            self._P,
            y,
            held,
            across,
            delayed,
            self.F,
            self.B,
            self.H,
            self.D,
            y_eq,
            self.u_eq,
            self.r_diag,
            self.Q,
            available,
            self.gate,
        )
        self._out_x = self._full(x_out)
        self._out_p = p_out
        return accepted, nis_sensor, nis, dof

    def _predict(self, currents) -> None:
        self._x, self._P = kf_predict(
            self._x, self._P, self.F, self.B, np.ascontiguousarray(currents - self.u_eq), self.Q
        )
