"""The linear grey-box predictor of levitation data (``idgrey`` with a ``'K'`` model).

The grey-box model is the physics model linearised at the equilibrium of the
parameter set ``theta`` (as MATLAB's ``idgrey``: the matrices are functions of
the parameters)::

    A, B, C, D, y_eq = linearize(MaggyModel(theta)).reduced()      (10 states)
    Ad, Bd = zoh(A, B, Ts)                                          (exact ZOH)
    x_{k+1} = Ad x_k + Bd u_k + w_k
    y_{k+d} = y_eq + C x_k + D u_k + e_k                            (d: sensor delay)

and its one-step predictor is the steady-state Kalman predictor in innovation
form::

    eps_k = y_{k+d} - y_eq - C xh_k - D u_k
    xh_{k+1} = Ad xh_k + Bd u_k + K eps_k

:mod:`~maglev_ros.greybox.dynamic` fits it; :mod:`~maglev_ros.greybox.nonlinear`
builds the full model's predictor on the same gain.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.linalg import solve_discrete_are

from ..physics.board_processing import BoardProcessing, augment_exact
from ..physics.discretization import zoh
from ..physics.equilibria import find_equilibria
from ..physics.linearization import FD_STEP, linearize
from ..physics.model import MaggyModel
from .errors import GreyBoxError
from .parameters import ParameterVector

__all__ = [
    'MEASUREMENTS',
    'GreyBoxSystem',
    'LevitationExperiment',
    'LinearGreyBoxProblem',
    'noise_level',
]

#: Measurement models: the raw field, or a V4x PC-control firmware's processed field.
MEASUREMENTS = ('raw', 'board')


#: Noise of a board-filtered reading beyond its filter state, in its noise levels
#: (the float32 rounding: none to speak of; small and positive for the Riccati equation)
FILTERED_READING = 0.01

#: s of unchanging coil currents that mark a levitation record's loop as not acting
COILS_IDLE_S = 0.1


@dataclass(frozen=True)
class LevitationExperiment:
    """One record of the levitating magnet under feedback.

    Attributes
    ----------
    u : ndarray, shape (N, n_s)
        Measured coil currents, A.
    y : ndarray, shape (N, 3 k)
        Sensor readings [Bx_0, By_0, Bz_0, Bx_1, ...], T.
    name : str
        For messages and plots.
    Ts : float
        Sample time, s.
    sensors : tuple of int or None
        Which of the parameter set's sensors ``y`` holds (None: all).
    """

    u: np.ndarray
    y: np.ndarray
    name: str = 'levitation'
    Ts: float = 2e-4
    sensors: tuple[int, ...] | None = None

    def __post_init__(self):
        u = np.ascontiguousarray(self.u, dtype=float)
        y = np.ascontiguousarray(self.y, dtype=float)
        if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
            raise GreyBoxError(
                f'{self.name}: u (N, n_s) and y (N, 3 k) must have as many rows, '
                f'got {u.shape} and {y.shape}'
            )
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise GreyBoxError(f'{self.name}: currents and fields must be finite')
        if not (np.isfinite(self.Ts) and self.Ts > 0):
            raise GreyBoxError(f'{self.name}: Ts must be positive, got {self.Ts!r}')
        object.__setattr__(self, 'u', u)
        object.__setattr__(self, 'y', y)
        if self.sensors is not None:
            object.__setattr__(self, 'sensors', tuple(int(k) for k in self.sensors))
            if y.shape[1] != 3 * len(self.sensors):
                raise GreyBoxError(
                    f'{self.name}: {len(self.sensors)} sensors need {3 * len(self.sensors)} '
                    f'field channels, got {y.shape[1]}'
                )

    @property
    def samples(self) -> int:
        """Number of samples N."""
        return self.u.shape[0]

    def coils_idle(self, shortest: float = COILS_IDLE_S) -> tuple[float, float] | None:
        """Return the longest span in which no coil current changes at all, if any.

        A levitating magnet needs its loop every few milliseconds (the lateral
        modes' time constants are 20-35 ms), and a loop's commands move with
        the sensor noise every sample. Currents that all keep one value for
        longer mean the loop was not acting: the magnet was lost (the
        controller switched the coils off), or not yet lifted.

        Parameters
        ----------
        shortest : float, optional
            Shortest span reported, s (default :data:`COILS_IDLE_S`).

        Returns
        -------
        (start, duration) : tuple of float, or None
            Start (s from the first sample) and length (s) of the longest
            such span; None when none lasts ``shortest``.
        """
        same = np.all(self.u[1:] == self.u[:-1], axis=1)  # sample k+1 repeats sample k
        edges = np.flatnonzero(np.diff(np.concatenate([[0], same, [0]]).astype(np.int8)))
        if not len(edges):
            return None
        starts, ends = edges[::2], edges[1::2] + 1  # a run of repeats spans one sample more
        k = int(np.argmax(ends - starts))
        duration = (ends[k] - starts[k]) * self.Ts
        return (starts[k] * self.Ts, duration) if duration >= shortest else None

    def channels(self, sensor_count: int) -> np.ndarray:
        """Return the indices of y's columns in the model's output vector.

        Parameters
        ----------
        sensor_count : int
            Sensors of the parameter set.
        """
        chosen = range(sensor_count) if self.sensors is None else self.sensors
        return np.array([3 * k + a for k in chosen for a in range(3)], dtype=int)

    def split(self, fraction: float) -> tuple[LevitationExperiment, LevitationExperiment]:
        """Estimation (first ``fraction``) and validation (the rest) parts.

        Parameters
        ----------
        fraction : float
            Share of the samples in the first part.
        """
        n = int(round(self.samples * fraction))
        return tuple(
            LevitationExperiment(self.u[s], self.y[s], self.name, self.Ts, self.sensors)
            for s in (slice(0, n), slice(n, None))
        )


def noise_level(y: np.ndarray) -> np.ndarray:
    """Noise level per channel from second differences (robust, MAD), T rms, shape (3 k,).

    A white sequence's second difference has 6 times its variance; a smooth
    motion at 5 kHz hardly contributes.

    Parameters
    ----------
    y : array_like, shape (N, 3 k)
        Readings, T.
    """
    d2 = np.diff(np.asarray(y, dtype=float), n=2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return np.maximum(1.4826 * mad / np.sqrt(6.0), 1e-9)


@njit(cache=True)
def _innovations(ad, bd, gain, c, d, y0, u, y, delay, out):  # pragma: no cover - compiled
    """Kalman predictor in innovation form; fills ``out`` (N - delay, p) with eps_k."""
    n = ad.shape[0]
    m = bd.shape[1]
    p = c.shape[0]
    x = np.zeros(n)
    xn = np.zeros(n)
    e = np.zeros(p)
    for k in range(out.shape[0]):
        for i in range(p):
            s = y[k + delay, i] - y0[i]
            for j in range(n):
                s -= c[i, j] * x[j]
            for j in range(m):
                s -= d[i, j] * u[k, j]
            e[i] = s
            out[k, i] = s
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += ad[i, j] * x[j]
            for j in range(m):
                s += bd[i, j] * u[k, j]
            for j in range(p):
                s += gain[i, j] * e[j]
            xn[i] = s
        for i in range(n):
            x[i] = xn[i]


@dataclass(frozen=True)
class GreyBoxSystem:
    """The discrete linear grey-box of one parameter set (what ``idgrey``'s function returns).

    Attributes
    ----------
    Ad : ndarray, shape (10, 10)
    Bd : ndarray, shape (10, n_s)
    C : ndarray, shape (3 k, 10)
    D : ndarray, shape (3 k, n_s)
    K : ndarray, shape (10, 3 k)
        Stationary Kalman gain (innovation form).
    y_eq : ndarray, shape (3 k,)
        Field at the equilibrium, T.
    z_eq : float
        Equilibrium height, m.
    """

    Ad: np.ndarray
    Bd: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray
    y_eq: np.ndarray
    z_eq: float

    def innovations(self, u: np.ndarray, y: np.ndarray, delay: int) -> np.ndarray:
        """Prediction errors eps (N - delay, 3 k) of readings ``y`` given currents ``u``.

        Parameters
        ----------
        u : ndarray, shape (N, n_s)
            Coil currents, A.
        y : ndarray, shape (N, 3 k)
            Readings, T.
        delay : int
            Sensor delay, samples.
        """
        out = np.empty((u.shape[0] - delay, self.C.shape[0]))
        _innovations(self.Ad, self.Bd, self.K, self.C, self.D, self.y_eq, u, y, int(delay), out)
        return out


class LinearGreyBoxProblem:
    """The linear grey-box prediction-error problem over a parameter vector.

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
        Input-disturbance level ``q`` of the Kalman gain, A rms.
    burn : int
        Samples of each record left out of the criterion while the
        predictor's initial error dies out.
    measurement : {'raw', 'board'}
        ``raw``: the sensors' field as the physics model gives it; ``board``:
        after a V4x PC-control firmware's processing (baseline and coil
        feedthrough removed, x/y low-pass; :mod:`maglev_ros.physics.board_processing`).
    board_pairs : array_like, shape (3 k, 2), optional
        ``board``: the processed field per ampere of each coil pair, measured
        without the magnet (T/A; ``BoardProcessing.from_model``'s ``pairs``);
        default: the firmware's compensation taken as exact.
    """

    def __init__(
        self,
        vector: ParameterVector,
        experiments: Sequence[LevitationExperiment],
        delay: int,
        sigma: np.ndarray,
        process_noise: float = 1e-3,
        burn: int = 100,
        measurement: str = 'raw',
        board_pairs=None,
    ):
        if measurement not in MEASUREMENTS:
            raise GreyBoxError(
                f'measurement must be one of {", ".join(MEASUREMENTS)}, got {measurement!r}'
            )
        self.measurement = measurement
        self.board_pairs = None if board_pairs is None else np.asarray(board_pairs, float)
        #: finite-difference step of the linearisation (the numerical check changes it)
        self.fd_step = FD_STEP
        self.vector = vector
        self.experiments = tuple(experiments)
        self.delay = int(delay)
        self.sigma = np.asarray(sigma, dtype=float)
        self.process_noise = float(process_noise)
        self.burn = int(burn)
        self.free = vector.free_specs
        self.scale = np.array([s.scale for s in self.free])
        self.center = np.array([s.nominal for s in self.free])
        self.Ts = self.experiments[0].Ts
        self.channels = self.experiments[0].channels(len(vector.base.sensors))
        self.evaluations = 0
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # (z, residual)
        self._last_jacobian: tuple[np.ndarray, float, np.ndarray] | None = None

    def values(self, z: np.ndarray) -> dict[str, float]:
        """Parameter values of the scaled free vector ``z`` (theta = nominal + scale z).

        Parameters
        ----------
        z : array_like, shape (free,)
            Scaled free parameters.
        """
        return self.vector.values(self.center + self.scale * np.asarray(z))

    def system(self, values: dict[str, float]) -> GreyBoxSystem:
        """Return the discrete grey-box and its Kalman gain for parameter values.

        Parameters
        ----------
        values : dict
            Parameter values by name, SI (missing ones nominal).

        Raises
        ------
        GreyBoxError
            The parameter set has no equilibrium (the magnet cannot levitate).
        """
        self.evaluations += 1
        model = MaggyModel(self.vector.apply(values))
        found = find_equilibria(model)
        if not found:
            raise GreyBoxError(f'no equilibrium for {values}')
        lin = linearize(model, model.hover_state(found[0].z), step=self.fd_step).reduced()
        ad, bd = zoh(lin.A, lin.B, self.Ts)
        c = np.ascontiguousarray(lin.C[self.channels])
        d = np.ascontiguousarray(lin.D[self.channels])
        y_eq = lin.y_eq[self.channels]
        reading = self.sigma**2
        filter_noise = np.zeros(0)
        if self.measurement == 'board':
            pairs = self.vector.board_pairs(values)  # estimated, else as measured
            board = BoardProcessing.from_model(
                model,
                sensors=self.channels[::3] // 3,
                pairs=self.board_pairs if pairs is None else pairs,
            )
            y_eq = y_eq - board.baseline
            d = d - board.feedthrough
            filtered = board.filtered
            # the board filters at each of its 200 us steps inside the host sample
            ad, bd, c, d = augment_exact(lin.A, lin.B, c, d, board, filtered, self.Ts)
            # the sensor noise enters before the filter: noise of the filter
            # states, not of the readings (white-noise readings bias the fit
            # in closed loop, where the noise reaches the currents)
            sensor = board.sensor_noise(self.sigma[filtered], self.Ts)
            filter_noise = board.noise_injection(self.Ts) * sensor**2
            reading = np.where(filtered, (FILTERED_READING * self.sigma) ** 2, reading)
        q = (self.process_noise**2) * (bd @ bd.T) + 1e-30 * np.eye(ad.shape[0])
        q[ad.shape[0] - filter_noise.size :, ad.shape[0] - filter_noise.size :] += np.diag(
            filter_noise
        )
        r = np.diag(reading)
        p = solve_discrete_are(ad.T, c.T, q, r)
        gain = ad @ p @ c.T @ np.linalg.inv(c @ p @ c.T + r)
        return GreyBoxSystem(
            np.ascontiguousarray(ad),
            np.ascontiguousarray(bd),
            c,
            d,
            np.ascontiguousarray(gain),
            np.ascontiguousarray(y_eq),
            float(found[0].z),
        )

    def errors(self, values: dict[str, float]) -> list[np.ndarray]:
        """Prediction errors per experiment (burn-in left out), T.

        Parameters
        ----------
        values : dict
            Parameter values by name, SI.
        """
        sys_ = self.system(values)
        return [sys_.innovations(e.u, e.y, self.delay)[self.burn :] for e in self.experiments]

    def residual(self, z: np.ndarray) -> np.ndarray:
        """Weighted prediction errors, all experiments and channels, flattened.

        Parameters
        ----------
        z : array_like, shape (free,)
            Scaled free parameters.
        """
        z = np.array(z, dtype=float)
        if self._last is not None and np.array_equal(self._last[0], z):
            return self._last[1]  # the solver and the progress line ask for the same point
        try:
            errs = self.errors(self.values(z))
            r = np.concatenate([(e / self.sigma).ravel() for e in errs])
        except (GreyBoxError, np.linalg.LinAlgError, ValueError):
            r = np.full(self.residual_size, 1e3)
        self._last = (z, r)
        return r

    def jacobian(self, z: np.ndarray, step: float = 1e-2) -> np.ndarray:
        """Return d residual / d z by central differences (scaled units).

        Parameters
        ----------
        z : array_like, shape (free,)
            Scaled free parameters.
        step : float
            Difference step in parameter scales (the linearisation is itself a
            finite difference: a tiny step differentiates its noise).
        """
        z = np.array(z, dtype=float)
        last = self._last_jacobian
        if last is not None and np.array_equal(last[0], z) and last[1] == step:
            return last[2]  # the identifiability check's Jacobian is the first iteration's
        cols = []
        for p in range(z.size):
            zp, zm = z.copy(), z.copy()
            zp[p] += step
            zm[p] -= step
            cols.append((self.residual(zp) - self.residual(zm)) / (2 * step))
        if not cols:
            return np.zeros((self.residual_size, 0))
        jac = np.column_stack(cols)
        self._last_jacobian = (z, step, jac)
        return jac

    @property
    def residual_size(self) -> int:
        """Length of the residual vector."""
        return sum(
            (e.samples - self.delay - self.burn) * self.channels.size for e in self.experiments
        )
