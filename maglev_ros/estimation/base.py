"""What every estimator shares: timing of the delayed reading, freezes, gating counts, NIS.

Timing (``sensor_delay = 1``, the board): the sample arriving at k carries the
fields measured at k-1 and the coil currents at k. The filter keeps its prior
for the instant of the reading: at sample k it *updates at k-1* with the reading
(the D feedthrough uses the currents of k-1, remembered from the previous
sample), then *predicts to k* with the currents of k-1 held over the sample
(ZOH). The published estimate is that prediction, x(k | readings up to k-1),
with its covariance; it is also the next sample's prior. Over that
prediction the coil current ramps from i(k-1) to i(k) (the coils' L / R lag):
both are known, and the prediction holds their mean (trapezoidal hold, far
closer than holding i(k-1) while the currents move). With
``sensor_delay = 0`` the reading is of k itself: the estimate is the
posterior at k and the prediction follows.

A sample that is the mean of ``average`` readings (N > 1, the KF only; the
reading delay is then one reading, 1 / N of a sample): its readings are of
the states from the previous sample's instant on, so the prior is that
instant's, as with a delayed reading, and the published estimate is the
prediction to the sample's own instant. The sample's currents are the
group's mean: they are held over the group for the update (the feedthrough
of the mean reading) and for the prediction alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ..physics import linearize
from ..physics.discretization import zoh
from ..physics.linearization import REDUCED_STATES
from .config import EstimatorConfig
from .freeze import FreezeDetector

__all__ = ['DELAY_MEAN', 'Estimator', 'EstimatorStatus', 'nis_band']

#: The readings' timing when a sample is the mean of a group of readings (0 and 1:
#: ``sensor_delay``).
DELAY_MEAN = 2


def nis_band(dof: int, probability: float = 0.99) -> tuple[float, float]:
    """Two-sided chi-square band of a NIS sum with ``dof`` degrees of freedom.

    Parameters
    ----------
    dof : int
        Degrees of freedom.
    probability : float
        Probability inside the band.

    Returns
    -------
    low, high : float
        ``chi2.ppf((1 -+ probability) / 2, dof)``.
    """
    tail = (1.0 - probability) / 2.0
    return float(chi2.ppf(tail, dof)), float(chi2.ppf(1.0 - tail, dof))


@dataclass(frozen=True)
class EstimatorStatus:
    """Diagnostics snapshot of an estimator.

    Attributes
    ----------
    samples : int
        Samples processed.
    rejected : tuple of int
        Readings rejected by the chi-square gate, per sensor.
    missing : tuple of int
        Readings missing or frozen (not used), per sensor.
    frozen : tuple of int
        Indices of the sensors frozen now.
    freeze_events : tuple of int
        Freezes detected per sensor since reset.
    nis_window : float
        Sum of the NIS over the last ``nis_window`` samples.
    nis_dof : int
        Degrees of freedom of that sum (3 per accepted reading).
    nis_band : tuple of float
        Its two-sided 99 % chi-square band.
    restarts : int
        Times the filter restarted from its prior after ``lost_samples``
        samples without an accepted reading (a lost magnet, a dead link).
    unaccepted : int
        Samples since a reading was last accepted.
    """

    samples: int
    rejected: tuple
    missing: tuple
    frozen: tuple
    freeze_events: tuple
    nis_window: float
    nis_dof: int
    nis_band: tuple
    restarts: int = 0
    unaccepted: int = 0

    @property
    def nis_ok(self) -> bool:
        """True when the window's NIS lies in its 99 % band (or the window is empty)."""
        return self.nis_dof == 0 or self.nis_band[0] <= self.nis_window <= self.nis_band[1]

    def frozen_names(self) -> tuple[str, ...]:
        """Names of the frozen sensors: ``sensor_<k>``."""
        return tuple(f'sensor_{k}' for k in self.frozen)


class Estimator:
    """Base of the KF, EKF and UKF: sample handling, freezes, counts, NIS window.

    Parameters
    ----------
    model : MaggyModel
        The model the estimator believes (a private copy is used: kernel
        scratch space is not shared with a simulator in another thread).
    config : EstimatorConfig, optional
    linear : LinearModel, optional
        Its 12-state linearisation about the equilibrium (computed if not given).
    """

    def __init__(self, model, config: EstimatorConfig | None = None, linear=None):
        self.config = config or EstimatorConfig()
        self.model = model.with_options()
        lin = linear if linear is not None else linearize(self.model)
        self.linear = lin.reduced() if lin.A.shape[0] == 12 else lin
        self.x_eq = np.array(self.linear.x_eq, dtype=float)
        self.u_eq = np.array(self.linear.u_eq, dtype=float)
        self.y_eq = np.array(self.linear.y_eq, dtype=float)
        self.reduced = np.array(REDUCED_STATES, dtype=np.int64)
        self.n_reduced = len(REDUCED_STATES)
        self.n_outputs = self.model.n_outputs
        self.n_inputs = self.model.n_inputs
        self.n_sensors = self.n_outputs // 3
        #: index of the magnet-strength state (None without it), then the bias states
        self.strength_index = self.n_reduced if self.config.magnet_strength else None
        self.bias_start = self.n_reduced + (1 if self.config.magnet_strength else 0)
        self.n_states = self.bias_start + (self.n_outputs if self.config.bias_states else 0)
        #: the board's processing (measurement 'board'), its filter states after the biases
        self.board = None
        self.filter_start = self.n_states
        if self.config.measurement == 'board':
            from ..physics.board_processing import BoardProcessing

            self.board = BoardProcessing.from_model(self.model)
            self.n_states += int(self.board.filtered.sum())
        self.dt = self.config.dt
        #: how the readings stand to the sample (:data:`DELAY_MEAN`: a group's mean)
        self.delay_mode = DELAY_MEAN if self.config.average > 1 else self.config.sensor_delay
        self.r_diag = np.full(self.n_outputs, self.config.measurement_variance)
        self.gate = (
            np.inf
            if self.config.gate_probability >= 1.0
            else float(chi2.ppf(self.config.gate_probability, 3))
        )
        self.freeze = FreezeDetector(self.n_sensors, self.config.freeze_samples)
        self._band_cache: dict[int, tuple[float, float]] = {}
        self.reset()

    # ------------------------------------------------------------------ set-up
    def initial_covariance(self) -> np.ndarray:
        """Return the initial P from the configured standard deviations, shape (n, n)."""
        c = self.config
        std = [c.initial_position] * 3 + [c.initial_angle] * 2
        std += [c.initial_velocity] * 3 + [c.initial_rate] * 2
        std += [c.initial_strength] * (self.bias_start - self.n_reduced)
        axis_std = (c.initial_bias_xy, c.initial_bias_xy, c.initial_bias)  # per sensor x y z
        std += [axis_std[j % 3] for j in range(self.filter_start - self.bias_start)]
        std += [c.initial_bias_xy] * (self.n_states - self.filter_start)  # board x/y filters
        return np.diag(np.square(std))

    def disturbance_matrix(self) -> np.ndarray:
        """Continuous input matrix of the process noise, shape (10, 4 + 5).

        Columns: the coil currents (B), then unit accelerations of vx, vy, vz,
        wx, wy (standard deviations: :meth:`disturbance_std`).
        """
        g = np.zeros((self.n_reduced, self.n_inputs + 5))
        g[:, : self.n_inputs] = self.linear.B
        for j in range(5):
            g[5 + j, self.n_inputs + j] = 1.0
        return g

    def disturbance_std(self) -> np.ndarray:
        """Return the standard deviations of the process-noise inputs, held over a sample."""
        c = self.config
        return np.array(
            [c.current_noise] * self.n_inputs
            + [c.acceleration_noise] * 2
            + [c.vertical_acceleration_noise]
            + [c.angular_acceleration_noise] * 2
        )

    def process_noise(self, gd: np.ndarray) -> np.ndarray:
        """Q from the discretised disturbance matrix ``gd`` (10, 9), strength and bias walks added.

        Parameters
        ----------
        gd : ndarray, shape (10, 9)
            ZOH-discretised :meth:`disturbance_matrix`.
        """
        q = np.zeros((self.n_states, self.n_states))
        std = self.disturbance_std()
        q[: self.n_reduced, : self.n_reduced] = (gd * std**2) @ gd.T
        for i in range(self.n_reduced, self.bias_start):
            q[i, i] = self.config.strength_walk**2
        for i in range(self.bias_start, self.filter_start):
            q[i, i] = self.config.bias_walk**2
        return 0.5 * (q + q.T)

    def discrete_process_noise(self) -> np.ndarray:
        """Return Q over one sample from the ZOH-discretised disturbance matrix, (n, n)."""
        _, gd = zoh(self.linear.A, self.disturbance_matrix(), self.dt)
        return self.process_noise(gd)

    # ------------------------------------------------------------------ state
    def reset(self, x0=None) -> None:
        """Restart: state at ``x0`` (12-state; default the equilibrium), P initial.

        Parameters
        ----------
        x0 : array_like, shape (12,), optional
            Initial estimate.
        """
        dx = np.zeros(self.n_states)
        if x0 is not None:
            full = np.asarray(x0, dtype=float)
            if full.shape != (12,) or not np.all(np.isfinite(full)):
                raise ValueError(f'x0 must be 12 finite numbers, got {x0!r}')
            dx[: self.n_reduced] = (full - self.x_eq)[self.reduced]
        self._set_state(dx, self.initial_covariance())
        self.freeze.reset()
        self._prev_currents = None
        self.samples = 0
        self.rejected = np.zeros(self.n_sensors, dtype=np.int64)
        self.missing = np.zeros(self.n_sensors, dtype=np.int64)
        self.restarts = 0
        self.unaccepted = 0
        w = self.config.nis_window
        self._nis_ring = np.zeros(w)
        self._dof_ring = np.zeros(w, dtype=np.int64)
        self.last_nis = 0.0
        self.last_dof = 0
        self.last_accepted = np.zeros(self.n_sensors, dtype=bool)
        self.last_nis_sensor = np.full(self.n_sensors, np.nan)
        self._out_x = self.x_eq.copy()
        self._out_p = self.covariance.copy()

    # subclasses: the filter's own state
    def _set_state(self, dx: np.ndarray, P: np.ndarray) -> None:
        raise NotImplementedError

    @property
    def deviation(self) -> np.ndarray:
        """Filter state: reduced deviation from the equilibrium (+ biases), shape (n,)."""
        raise NotImplementedError

    @property
    def covariance(self) -> np.ndarray:
        """Filter covariance, shape (n, n)."""
        raise NotImplementedError

    def _update(self, y, currents, available):
        """Measurement update; returns (accepted, nis_sensor, nis, dof)."""
        raise NotImplementedError

    def _predict(self, currents) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------------ stepping
    def step(self, y, currents) -> np.ndarray:
        """Process one complete sample and return the state estimate.

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
        y = np.asarray(y, dtype=float)
        currents = np.asarray(currents, dtype=float)
        if y.shape != (self.n_outputs,):
            raise ValueError(f'y must have {self.n_outputs} readings, got shape {y.shape}')
        if currents.shape != (self.n_inputs,) or not math.isfinite(currents.sum()):
            raise ValueError(f'currents must be {self.n_inputs} finite numbers, got {currents!r}')
        available = self.freeze.check(y)
        delayed = self.config.sensor_delay == 1
        if self.delay_mode == DELAY_MEAN:  # the group's mean currents, over the group
            held = across = currents
        else:
            held = currents if not delayed or self._prev_currents is None else self._prev_currents
            # over the sample k-1 -> k the coil current ramps from i(k-1) to i(k): with
            # the delayed reading both ends are known, so the prediction holds their mean
            across = 0.5 * (held + currents) if delayed else currents
        accepted, nis_sensor, nis, dof = self._sample(y, held, across, available, delayed)
        if not available.all():
            self.missing += ~available
        if dof < 3 * available.sum():
            self.rejected += available & ~accepted
        self._record(currents, accepted, nis_sensor, nis, dof)
        return self._out_x

    def _checked_sample(self, y, currents) -> tuple[np.ndarray, np.ndarray]:
        """Return ``y`` (3 k,) and ``currents`` (n_s,) as C arrays; ValueError if not.

        C-contiguous always: one compiled signature (a strided row, e.g. of a
        burst's array, would compile a kernel again: seconds in a real-time loop).
        """
        y = np.ascontiguousarray(y, dtype=float)
        currents = np.ascontiguousarray(currents, dtype=float)
        if y.shape != (self.n_outputs,):
            raise ValueError(f'y must have {self.n_outputs} readings, got shape {y.shape}')
        if currents.shape != (self.n_inputs,) or not math.isfinite(currents.sum()):
            raise ValueError(f'currents must be {self.n_inputs} finite numbers, got {currents!r}')
        return y, currents

    def step_many(self, ys, currents) -> tuple[np.ndarray, np.ndarray]:
        """Process n complete samples in order, as n calls of :meth:`step`.

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
        ys, currents = self._checked_many(ys, currents)
        n = ys.shape[0]
        x = np.empty((n, 12))
        p = np.empty((n, self.n_states, self.n_states))
        for i in range(n):
            x[i] = self.step(ys[i], currents[i])
            p[i] = self._out_p
        return x, p

    def _checked_many(self, ys, currents) -> tuple[np.ndarray, np.ndarray]:
        """Return ``ys`` (n, 3 k) and ``currents`` (n, n_s) as C arrays; ValueError if not."""
        ys = np.ascontiguousarray(ys, dtype=float)
        currents = np.ascontiguousarray(currents, dtype=float)
        n = ys.shape[0] if ys.ndim == 2 else -1
        if ys.shape[1:] != (self.n_outputs,) or currents.shape != (n, self.n_inputs):
            raise ValueError(
                f'ys (n, {self.n_outputs}) and currents (n, {self.n_inputs}) must have as '
                f'many rows, got shapes {ys.shape} and {currents.shape}'
            )
        if not math.isfinite(currents.sum()):
            bad = int(np.nonzero(~np.isfinite(currents).all(axis=1))[0][0])
            raise ValueError(
                f'currents must be finite numbers, got {currents[bad]!r} in row {bad}'
            )
        return ys, currents

    def _record(self, currents, accepted, nis_sensor, nis, dof) -> None:
        """Keep a stepped sample's NIS, acceptance and currents; restart when lost."""
        slot = self.samples % self.config.nis_window
        self._nis_ring[slot] = nis
        self._dof_ring[slot] = dof
        self.last_nis, self.last_dof = nis, dof
        self.last_accepted, self.last_nis_sensor = accepted, nis_sensor
        self._prev_currents = currents
        self.samples += 1
        self.unaccepted = 0 if dof else self.unaccepted + 1
        if self.unaccepted >= self.config.lost_samples:
            self._restart()

    def _restart(self) -> None:
        """Start again from the prior at the equilibrium (counts kept; see ``lost_samples``)."""
        self._set_state(np.zeros(self.n_states), self.initial_covariance())
        self._out_x = self.x_eq.copy()
        self._out_p = self.covariance
        self.restarts += 1
        self.unaccepted = 0

    def _sample(self, y, held, across, available, delayed):
        """Update with ``y`` (currents ``held``), predict with ``across``, publish.

        ``held``: the currents at the reading's instant (for the D feedthrough);
        ``across``: the currents held over the prediction.
        """
        result = self._update(y, held, available)
        if delayed:
            self._predict(across)
            self._out_x = self._full(self.deviation)
            self._out_p = self.covariance
        else:
            self._out_x = self._full(self.deviation)
            self._out_p = self.covariance
            self._predict(across)
        return result

    def predict_only(self, currents) -> np.ndarray:
        """Advance one sample without a reading (the whole sample is missing).

        Parameters
        ----------
        currents : array_like, shape (n_s,)
            Measured coil currents, A.
        """
        nan = np.full(self.n_outputs, np.nan)
        return self.step(nan, currents)

    # ------------------------------------------------------------------ outputs
    @property
    def state(self) -> np.ndarray:
        """Last published estimate, 12-state (copy)."""
        return self._out_x.copy()

    @property
    def state_covariance(self) -> np.ndarray:
        """Covariance of the last estimate's reduced states (and biases), shape (n, n)."""
        return self._out_p.copy()

    def state_std(self) -> np.ndarray:
        """Return the standard deviations of the last estimate's reduced states, shape (10,)."""
        return np.sqrt(np.diag(self._out_p)[: self.n_reduced])

    def _full(self, dx: np.ndarray) -> np.ndarray:
        x = self.x_eq.copy()
        x[self.reduced] += dx[: self.n_reduced]
        return x

    def status(self) -> EstimatorStatus:
        """Diagnostics: rejected/missing counts, frozen sensors, windowed NIS."""
        filled = min(self.samples, self.config.nis_window)
        dof = int(self._dof_ring[:filled].sum())
        if dof not in self._band_cache:
            self._band_cache[dof] = nis_band(dof) if dof else (0.0, 0.0)
        return EstimatorStatus(
            samples=self.samples,
            rejected=tuple(int(v) for v in self.rejected),
            missing=tuple(int(v) for v in self.missing),
            frozen=tuple(int(k) for k in np.flatnonzero(self.freeze.frozen)),
            freeze_events=tuple(int(v) for v in self.freeze.events),
            nis_window=float(self._nis_ring[:filled].sum()),
            nis_dof=dof,
            nis_band=self._band_cache[dof],
            restarts=self.restarts,
            unaccepted=self.unaccepted,
        )
