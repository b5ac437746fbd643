"""Linear Kalman filter on the reduced 10-state model about the equilibrium."""

from __future__ import annotations

import numpy as np

from ..physics.discretization import zoh
from . import linear_kernels as lk
from .base import Estimator
from .group_mean import group_mean_model
from .linear_kernels import (
    kf_packed_step,
    kf_packed_steps,
    kf_predict_into,
    kf_sample_into,
    kf_update_into,
    packed_sizes,
)

__all__ = ['KalmanEstimator']

_empty = np.empty


class KalmanEstimator(Estimator):
    """KF on ``dx = x - x_eq`` (10 reduced states, optional 9 sensor-bias states).

    Model, discretised exactly (ZOH) at the sample rate::

        dx(k+1) = Ad dx(k) + Bd (i(k) - u_eq)
        y(k)    = y_eq + C dx(k) + D (i(k) - u_eq) [+ b]     (D: the coils' direct field)

    With ``average`` N > 1 each sample is the mean of N readings over the
    sample: ``C`` and ``D`` become the group mean's ``C_bar`` and ``D_bar``
    (:mod:`~maglev_ros.estimation.group_mean`), the filter's prior is at the
    group's start and the sample's currents (the group's mean) are held over it
    for the update and the prediction.

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
        super().__init__(model, config, linear)
        lk.load_packed_step()  # compiled (or loaded) now, not at import or first sample

    def _build(self) -> None:
        """Build the model matrices and the packed arrays (:func:`linear_kernels.packed_sizes`)."""
        n, nr, m, mi = self.n_states, self.n_reduced, self.n_outputs, self.n_inputs
        k, w = self.n_sensors, self.config.nis_window
        layout = packed_sizes(n, m, mi, k, w, nr)
        self._ints = np.zeros(layout['ints']['size'], dtype=np.int64)
        self._floats = np.zeros(layout['floats']['size'])  # the model, then the state

        def section(array, table, name, shape=None):
            a, b = table[name]
            view = array[a:b]
            return view.reshape(shape) if shape is not None else view

        it, fl = layout['ints'], layout['floats']
        self.F = section(self._floats, fl, 'F', (n, n))
        self.B = section(self._floats, fl, 'B', (n, mi))
        self.H = section(self._floats, fl, 'H', (m, n))
        self.D = section(self._floats, fl, 'D', (m, mi))
        self.Q = section(self._floats, fl, 'Q', (n, n))
        self._write_model()
        for name, value in (
            ('y_eq', self.y_eq),
            ('u_eq', self.u_eq),
            ('r_diag', self.r_diag),
            ('x_eq', self.x_eq),
            ('p_init', self.initial_covariance().ravel()),
            ('gate', [min(self.gate, np.finfo(float).max)]),
        ):
            section(self._floats, fl, name)[:] = value
        self._p_init = section(self._floats, fl, 'p_init', (n, n))
        self._packed_y_eq = section(self._floats, fl, 'y_eq')
        self._ints[: lk.INT_HEADER] = [
            n, m, mi, k, w, nr,
            self.delay_mode, self.freeze.run, self.config.lost_samples,
            0, 0, 0, 0, 0,
            self.strength_index is None,  # else H is linearised in Python each sample
        ]  # fmt: skip
        section(self._ints, it, 'reduced')[:] = self.reduced
        self._accepted = section(self._ints, it, 'accepted')
        self._dof = section(self._ints, it, 'dof_ring')
        self._x = section(self._floats, fl, 'x')
        self._P = section(self._floats, fl, 'P', (n, n))
        self._p_out = section(self._floats, fl, 'out_p', (n, n))
        self._out_p_at = fl['out_p'][0]
        self._prev = section(self._floats, fl, 'prev')
        self._nis_sensor = section(self._floats, fl, 'nis_sensor')
        self._nis = section(self._floats, fl, 'nis_ring')
        # the freeze detector's history and the counts live in the packed arrays too
        self._missing = section(self._ints, it, 'missing')
        self._rejected = section(self._ints, it, 'rejected')
        f = self.freeze
        f._last = section(self._floats, fl, 'last', (k, 3))
        f.runs = section(self._ints, it, 'runs')
        f.events = section(self._ints, it, 'events')

    def _write_model(self) -> None:
        """Compute F, B, H, D, Q (and ``y_eq`` for the board) into the packed arrays."""
        n, nr, m, mi = self.n_states, self.n_reduced, self.n_outputs, self.n_inputs
        lin = self.linear
        g = self.disturbance_matrix()
        ad, gd = zoh(lin.A, g, self.dt)  # g's first columns are B: gd's are Bd
        F = np.eye(n)
        F[:nr, :nr] = ad
        B = np.zeros((n, mi))
        B[:nr] = gd[:, :mi]
        H = np.zeros((m, n))
        H[:, :nr] = lin.C
        if self.filter_start > self.bias_start:
            H[:, self.bias_start : self.filter_start] = np.eye(m)
        self.C = np.ascontiguousarray(lin.C, dtype=float)
        self.y_eq = np.array(lin.y_eq, dtype=float)
        self.magnet_field = self.y_eq - self.model.measurement(
            self.x_eq, self.u_eq, with_magnet=False
        )
        if self.strength_index is not None:
            H[:, self.strength_index] = self.magnet_field
        D = np.array(lin.D, dtype=float)
        if self.config.average > 1:  # a mean of readings over the sample: of its start
            H[:, :nr], D = group_mean_model(lin.A, lin.B, lin.C, D, self.dt, self.config.average)
        Q = self.process_noise(gd)
        if self.board is not None:  # the board's processed field (BoardProcessing)
            D = self._board_model(F, B, H, D, Q, gd)
        self.F[:], self.B[:], self.H[:], self.D[:] = F, B, H, D
        self.Q[:] = 0.5 * (Q + Q.T)

    def use_board(self, board) -> None:
        """Model this board's processing from now on, and restart (:meth:`reset`).

        For a board whose processing was measured (its coil pairs' feedthrough:
        ``BoardProcessing.from_model(model, pairs=...)``). The packed arrays
        keep their place: the loop's compiled step sees the new model.

        Parameters
        ----------
        board : BoardProcessing
            Of the estimator's channels.

        Raises
        ------
        ValueError
            If the estimator's measurement is not ``board``, or the board's
            channels differ from the estimator's.
        """
        if self.board is None:
            raise ValueError("the estimator's measurement is 'raw': it models no board")
        if board.baseline.shape != self.board.baseline.shape or not np.array_equal(
            board.filtered, self.board.filtered
        ):
            raise ValueError('the board must have the channels of the estimator')
        self.board = board
        self._write_model()
        self._packed_y_eq[:] = self.y_eq
        self.reset()

    def reset(self, x0=None) -> None:
        """Restart: as :meth:`Estimator.reset`.

        Parameters
        ----------
        x0 : array_like, shape (12,), optional
            Initial estimate.
        """
        super().reset(x0)
        self._packed = (self._floats, self._ints, self.freeze.frozen)

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
        self._x[:] = dx
        self._P[:] = P

    # the record of the last sample, kept in the packed arrays
    samples = property(
        lambda self: int(self._ints[lk.I_SAMPLES]),
        lambda self, v: self._ints.__setitem__(lk.I_SAMPLES, v),
        doc='Samples processed.',
    )
    unaccepted = property(
        lambda self: int(self._ints[lk.I_UNACCEPTED]),
        lambda self, v: self._ints.__setitem__(lk.I_UNACCEPTED, v),
        doc='Samples since a reading was last accepted.',
    )
    restarts = property(
        lambda self: int(self._ints[lk.I_RESTARTS]),
        lambda self, v: self._ints.__setitem__(lk.I_RESTARTS, v),
        doc='Restarts from the prior (see ``lost_samples``).',
    )
    last_dof = property(
        lambda self: int(self._ints[lk.I_LAST_DOF]),
        lambda self, v: self._ints.__setitem__(lk.I_LAST_DOF, v),
        doc="Degrees of freedom of the last sample's NIS (3 per accepted reading).",
    )
    last_nis = property(
        lambda self: float(self._floats[-1]),
        lambda self, v: self._floats.__setitem__(-1, v),
        doc="NIS of the last sample's accepted readings.",
    )
    last_accepted = property(
        lambda self: self._accepted.astype(bool),
        lambda self, v: self._accepted.__setitem__(slice(None), v),
        doc='Sensors whose reading the last sample accepted, shape (k,).',
    )
    last_nis_sensor = property(
        lambda self: self._nis_sensor.copy(),
        lambda self, v: self._nis_sensor.__setitem__(slice(None), v),
        doc="Each sensor's NIS in the last sample (NaN: missing), shape (k,).",
    )
    _nis_ring = property(
        lambda self: self._nis, lambda self, v: self._nis.__setitem__(slice(None), v)
    )
    _dof_ring = property(
        lambda self: self._dof, lambda self, v: self._dof.__setitem__(slice(None), v)
    )
    missing = property(
        lambda self: self._missing,
        lambda self, v: self._missing.__setitem__(slice(None), v),
        doc='Readings missing or frozen, per sensor.',
    )
    rejected = property(
        lambda self: self._rejected,
        lambda self, v: self._rejected.__setitem__(slice(None), v),
        doc='Readings rejected by the gate, per sensor.',
    )
    _out_p = property(
        lambda self: self._p_out, lambda self, v: self._p_out.__setitem__(slice(None), v)
    )

    @property
    def _prev_currents(self):
        return self._prev.copy() if self._ints[lk.I_HAS_PREV] else None

    @_prev_currents.setter
    def _prev_currents(self, value) -> None:
        self._ints[lk.I_HAS_PREV] = value is not None
        if value is not None:
            self._prev[:] = value

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
        nu = np.ascontiguousarray(np.where(np.isfinite(nu), nu, 0.0))
        xp, Pp = np.empty_like(self._x), np.empty_like(self._P)
        accepted, nis_sensor, nis, dof = kf_update_into(
            self._x, self._P, self.H, self.r_diag, nu, available, self.gate, xp, Pp
        )
        self._x[:], self._P[:] = xp, Pp
        return accepted, nis_sensor, nis, dof

    def _predict(self, currents) -> None:
        xn, Pn = np.empty_like(self._x), np.empty_like(self._P)
        u = np.ascontiguousarray(currents - self.u_eq, dtype=float)
        kf_predict_into(self._x, self._P, self.F, self.B, u, self.Q, xn, Pn)
        self._x[:], self._P[:] = xn, Pn

    def step(self, y, currents) -> np.ndarray:
        """Process one complete sample and return the state estimate.

        As :meth:`Estimator.step`; without the magnet-strength state the whole
        sample, bookkeeping included, is one compiled call on packed arrays
        (:func:`linear_kernels.kf_packed_step`: the same operations, so the
        same numbers), a few microseconds a sample.

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
        out = _empty(12)
        try:  # float64 C arrays go straight in; anything else is a TypeError, not a compile
            if kf_packed_step(y, currents, *self._packed, out):
                self._out_x = out
                return out  # the prior's x_eq if the filter restarted
        except TypeError:  # e.g. a list, or a strided row of a burst's array
            y = np.ascontiguousarray(y, dtype=float)
            currents = np.ascontiguousarray(currents, dtype=float)
            if y.ndim == 1 == currents.ndim and kf_packed_step(y, currents, *self._packed, out):
                self._out_x = out
                return out
        # the magnet-strength state (its H is linearised here), or an input to name
        return super().step(y, currents)

    def step_many(self, ys, currents) -> tuple[np.ndarray, np.ndarray]:
        """Process n complete samples in order, as n calls of :meth:`step`, in one call.

        Without the magnet-strength state, one compiled call for them all
        (:func:`linear_kernels.kf_packed_steps`, the same numbers as
        :meth:`step`): a burst of a real-time simulator.

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
        kf_packed_steps(ys, currents, *self._packed, x, p, self._out_p_at)
        self._out_x = x[-1].copy()
        return x, p

    def _sample(self, y, held, across, available, delayed):
        """Update, predict and publish with :func:`linear_kernels.kf_sample_into`."""
        y_eq = self._linearize_strength()
        n = self.n_states
        xp, Pp, xn, Pn = np.empty(n), np.empty((n, n)), np.empty(n), np.empty((n, n))
        accepted, nis_sensor, nis, dof = kf_sample_into(
            self._x,
            self._P,
            y,
            np.ascontiguousarray(held, dtype=float),
            np.ascontiguousarray(across, dtype=float),
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
            xp,
            Pp,
            xn,
            Pn,
        )
        self._x[:], self._P[:] = xn, Pn
        self._out_x = self._full(xn if delayed else xp)
        self._out_p = Pn if delayed else Pp
        return accepted, nis_sensor, nis, dof
