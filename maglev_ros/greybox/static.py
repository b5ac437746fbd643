"""Static calibration: the field against the coil currents, magnet absent or held fixed.

With the magnet absent or held still, a sensor reading is affine in the coil
currents (the fields of loops add and scale with their currents)::

    y_i = c(theta) + M(theta)^T u_{i-d} + e_i,     y: (3 k,), u: (n_s,)

``c`` holds the permanent magnets, the held magnet and the offsets; ``M`` the
coils' fields at the sensors through the sensors' rotation and gain; ``d`` the
sensor delay in samples. So the prediction-error criterion over N samples
depends on the data only through the regression's moments
``Z^T Z`` and ``Z^T Y`` (``Z = [1, U]``, N x (n_s + 1)): with the unconstrained
affine estimate ``T_hat`` and the Cholesky factor ``L`` of ``Z^T Z``,

    sum_i |y_i - yhat_i(theta)|^2 = S_min + |L^T (T(theta) - T_hat)|_F^2,

exactly. The least-squares problem therefore has (n_s + 1) x 3 k residuals per
experiment whatever N, and its Jacobian needs the model at 2 x (free
parameters) parameter vectors only (central differences of ``T(theta)``, which
the compiled fast model evaluates in microseconds). Each channel is weighted by
its noise level, estimated from the affine fit's residuals.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..physics.model import MaggyModel
from ..physics.parameters import MaggyParameters
from .bounded_fit import fit_bounded, identified, spread
from .errors import GreyBoxError
from .identifiability import Identifiability, correlated_pairs
from .parameters import ParameterVector

__all__ = [
    'MAGNET_STATES',
    'StaticExperiment',
    'AffineStatistics',
    'ValidationFit',
    'StaticCalibration',
    'StaticProblem',
    'best_delay',
    'delay_costs',
    'calibrate_static',
    'fit_percent',
]

MAGNET_STATES = ('absent', 'fixed')
#: Height at which an absent magnet is "placed" (it has no field, any state will do), m.
_ABSENT_STATE = np.array([0.0, 0.0, 0.03] + [0.0] * 9)


@dataclass(frozen=True)
class StaticExperiment:
    """One record of the field against the coil currents.

    Attributes
    ----------
    u : ndarray, shape (N, n_s)
        Coil currents, A, order x+, x-, y+, y-.
    y : ndarray, shape (N, 3 k)
        Sensor readings [Bx_0, By_0, Bz_0, Bx_1, ...], T.
    magnet : {'absent', 'fixed'}
        The levitating magnet: absent, or held still somewhere.
    name : str
        For messages and plots (e.g. the bag's path).
    Ts : float
        Sample time, s.
    pose : tuple of float or None
        Fixed magnet: a guess of where it is held, (x, y, z, alpha, beta), m
        and rad (None: the nominal set's equilibrium).
    sensors : tuple of int or None
        Which of the parameter set's sensors ``y`` holds, in order (None: all).
    valid : ndarray of bool, shape (N,), or None
        Readings to use (False: left out, e.g. a frozen sensor); None: all.
    """

    u: np.ndarray
    y: np.ndarray
    magnet: str = 'absent'
    name: str = 'experiment'
    Ts: float = 2e-4
    pose: tuple[float, ...] | None = None
    sensors: tuple[int, ...] | None = None
    valid: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self):
        u = np.asarray(self.u, dtype=float)
        y = np.asarray(self.y, dtype=float)
        if self.magnet not in MAGNET_STATES:
            raise GreyBoxError(
                f'{self.name}: magnet must be absent or fixed for static calibration, '
                f'got {self.magnet!r}'
            )
        if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
            raise GreyBoxError(
                f'{self.name}: u (N, n_s) and y (N, 3 k) must have as many rows, '
                f'got {u.shape} and {y.shape}'
            )
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise GreyBoxError(f'{self.name}: currents and fields must be finite')
        object.__setattr__(self, 'u', u)
        object.__setattr__(self, 'y', y)
        if self.valid is not None:
            valid = np.asarray(self.valid, dtype=bool)
            if valid.shape != (u.shape[0],):
                raise GreyBoxError(
                    f'{self.name}: valid must have one flag per sample ({u.shape[0]}), '
                    f'got shape {valid.shape}'
                )
            object.__setattr__(self, 'valid', valid)
        if self.sensors is not None:
            object.__setattr__(self, 'sensors', tuple(int(k) for k in self.sensors))
            if y.shape[1] != 3 * len(self.sensors):
                raise GreyBoxError(
                    f'{self.name}: {len(self.sensors)} sensors need {3 * len(self.sensors)} '
                    f'field channels, got {y.shape[1]}'
                )

    def channels(self, sensor_count: int) -> np.ndarray:
        """Return the indices of y's columns in the model's output vector (3 per sensor).

        Parameters
        ----------
        sensor_count : int
            Sensors of the parameter set.
        """
        chosen = range(sensor_count) if self.sensors is None else self.sensors
        return np.array([3 * k + a for k in chosen for a in range(3)], dtype=int)

    @property
    def samples(self) -> int:
        """Number of samples N."""
        return self.u.shape[0]

    def split(self, fraction: float) -> tuple[StaticExperiment, StaticExperiment]:
        """Estimation (first ``fraction``) and validation (the rest) parts.

        Parameters
        ----------
        fraction : float
            Share of the samples in the first part.
        """
        n = int(round(self.samples * fraction))
        cut = [slice(0, n), slice(n, None)]
        return tuple(
            StaticExperiment(
                self.u[s],
                self.y[s],
                self.magnet,
                self.name,
                self.Ts,
                self.pose,
                self.sensors,
                None if self.valid is None else self.valid[s],
            )
            for s in cut
        )

    def frozen(self, min_run: int = 3, delay: int = 0) -> np.ndarray:
        """Return the readings of a frozen sensor, bool (N,).

        Under coil switching the Hall sensors sometimes repeat one reading
        until reset (the firmware resets after 20). A reading is marked when
        it belongs to a run of at least ``min_run`` identical readings of a
        sensor (all three axes exactly equal) during which the currents the
        readings should reflect (``delay`` samples earlier) change: every
        repeat of such a run is marked, the run's first reading is genuine
        and kept. Shorter runs are left alone (quantised noise repeats now and
        then), and so are repeats under unchanged currents (no sign of a freeze).

        Parameters
        ----------
        min_run : int
            Shortest run of identical readings taken as a freeze.
        delay : int
            Sensor delay, samples.
        """
        n = self.samples
        out = np.zeros(n, dtype=bool)
        for k in range(self.y.shape[1] // 3):
            block = self.y[:, 3 * k : 3 * k + 3]
            same = np.zeros(n, dtype=bool)
            same[1:] = np.all(block[1:] == block[:-1], axis=1)
            edges = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
            starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
            for a, b in zip(starts, ends, strict=True):
                if b - a < min_run - 1:
                    continue
                first = self.u[max(a - 1 - delay, 0)]
                cause = self.u[np.maximum(np.arange(a, b) - delay, 0)]
                if np.any(cause != first):
                    out[a:b] = True  # a freeze: all its repeats go (correlated errors)
        return out


def _regressors(u: np.ndarray) -> np.ndarray:
    return np.hstack([np.ones((u.shape[0], 1)), u])


def _shifted(exp: StaticExperiment, delay: int) -> tuple[np.ndarray, np.ndarray]:
    """Currents and (valid) readings paired with ``delay`` samples of sensor delay."""
    n = exp.samples - delay
    u, y = exp.u[:n], exp.y[delay:]
    if exp.valid is None:
        return u, y
    keep = exp.valid[delay:]
    return u[keep], y[keep]


@dataclass(frozen=True)
class AffineStatistics:
    """The moments of one experiment's affine regression (everything the fit needs).

    Attributes
    ----------
    samples : int
        Samples used (after the delay shift).
    delay : int
        Sensor delay, samples.
    theta_hat : ndarray, shape (n_s + 1, 3 k)
        Unconstrained affine estimate [c; M].
    root : ndarray, shape (n_s + 1, n_s + 1)
        Upper-triangular ``L^T`` with ``L L^T = Z^T Z``.
    residual_ss : ndarray, shape (3 k,)
        Residual sum of squares of the unconstrained fit per channel, T^2.
    sigma : ndarray, shape (3 k,)
        Noise level per channel, T rms.
    """

    samples: int
    delay: int
    theta_hat: np.ndarray
    root: np.ndarray
    residual_ss: np.ndarray
    sigma: np.ndarray

    @classmethod
    def of(cls, exp: StaticExperiment, delay: int) -> AffineStatistics:
        """Compute the statistics of ``exp`` for a given delay (samples).

        Parameters
        ----------
        exp : StaticExperiment
            The record.
        delay : int
            Sensor delay, samples.

        Raises
        ------
        GreyBoxError
            Too few samples, or currents that do not excite every coil
            independently (singular regression).
        """
        u, y = _shifted(exp, delay)
        z = _regressors(u)
        if z.shape[0] <= 2 * z.shape[1]:
            raise GreyBoxError(
                f'{exp.name}: {z.shape[0]} valid samples in this part are too few: the '
                f'affine fit of the field to {u.shape[1]} currents needs more than '
                f'{2 * z.shape[1]} (twice its {z.shape[1]} coefficients) in the estimation '
                'and in the validation part; record longer, or move the split with --split'
            )
        gram = z.T @ z
        try:
            lower = np.linalg.cholesky(gram)
        except np.linalg.LinAlgError:
            raise GreyBoxError(
                f'{exp.name}: the coil currents do not vary independently (every coil '
                'needs its own excitation)'
            ) from None
        if np.linalg.cond(gram) > 1e12:
            raise GreyBoxError(
                f'{exp.name}: the coil currents do not vary independently (every coil '
                'needs its own excitation)'
            )
        theta = np.linalg.solve(gram, z.T @ y)
        resid = y - z @ theta
        ss = np.einsum('ij,ij->j', resid, resid)
        sigma = np.sqrt(ss / (z.shape[0] - z.shape[1]))
        # a noise-free channel (simulation) would get infinite weight: floor it
        sigma = np.maximum(sigma, 1e-9)
        return cls(z.shape[0], delay, theta, lower.T.copy(), ss, sigma)


def best_delay(exp: StaticExperiment, max_delay: int = 5) -> int:
    """Return the sensor delay (samples) that best explains the readings by the currents.

    Chooses ``d`` in 0..max_delay minimising the affine regression's residual
    (currents at ``i - d`` against readings at ``i``).

    Parameters
    ----------
    exp : StaticExperiment
        The record.
    max_delay : int
        Largest delay tried, samples.
    """
    return _first_best(delay_costs(exp, max_delay))


def _first_best(costs: Sequence[float]) -> int:
    """Index of the smallest cost; a later one must be smaller by more than 1e-9 relative."""
    best, best_ss = 0, np.inf
    for d, ss in enumerate(costs):
        if ss < best_ss * (1 - 1e-9):
            best, best_ss = d, ss
    return best


def delay_costs(exp: StaticExperiment, max_delay: int = 5) -> tuple[float, ...]:
    """Return the affine regression's residual per sample for delays ``0..max_delay``.

    Parameters
    ----------
    exp : StaticExperiment
        The record.
    max_delay : int
        Largest delay tried, samples (fewer if the record is too short).
    """
    costs = []
    for d in range(max_delay + 1):
        if exp.samples - d <= 3 * (exp.u.shape[1] + 1):
            break
        costs.append(float(np.sum(AffineStatistics.of(exp, d).residual_ss / (exp.samples - d))))
    return tuple(costs)


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """NRMSE fit per column, percent: ``100 (1 - |y - yhat| / |y - mean(y)|)``.

    Parameters
    ----------
    y : ndarray, shape (N, p)
        Measured.
    yhat : ndarray, shape (N, p)
        Predicted.
    """
    err = np.linalg.norm(y - yhat, axis=0)
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    with np.errstate(divide='ignore', invalid='ignore'):
        return 100.0 * (1.0 - err / spread)


@dataclass(frozen=True)
class ValidationFit:
    """How well a parameter set predicts one experiment's validation part.

    Attributes
    ----------
    experiment : str
        Its name.
    fit : ndarray, shape (3 k,)
        NRMSE fit per channel, percent.
    rms : ndarray, shape (3 k,)
        RMS prediction error per channel, T.
    """

    experiment: str
    fit: np.ndarray
    rms: np.ndarray

    @property
    def mean_fit(self) -> float:
        """Mean fit over the channels, percent (channels without spread left out)."""
        return float(np.nanmean(self.fit))

    @property
    def total_rms(self) -> float:
        """RMS prediction error over every channel, T."""
        return float(np.sqrt(np.mean(self.rms**2)))


class StaticProblem:
    """The static prediction-error problem over a parameter vector.

    Parameters
    ----------
    vector : ParameterVector
        Parameters (the free ones are estimated); fixed-magnet experiments
        need its ``pose{e}.*`` entries (:func:`calibrate_static` adds them).
    experiments : sequence of StaticExperiment
        Estimation data.
    delays : sequence of int
        Sensor delay per experiment, samples.
    poses : sequence of int or None, optional
        Pose number (``pose{e}``) of each experiment, None where the magnet is
        absent (default: the fixed experiments numbered in order).
    """

    def __init__(
        self,
        vector: ParameterVector,
        experiments: Sequence[StaticExperiment],
        delays: Sequence[int],
        poses: Sequence[int | None] | None = None,
    ):
        self.vector = vector
        self.experiments = tuple(experiments)
        self.stats = tuple(
            AffineStatistics.of(e, d) for e, d in zip(self.experiments, delays, strict=True)
        )
        self.free = vector.free_specs
        self.scale = np.array([s.scale for s in self.free])
        self.center = np.array([s.nominal for s in self.free])
        n_s = vector.base.solenoids.count
        self._units = np.vstack([np.zeros(n_s), np.eye(n_s)])
        if poses is None:
            fixed = [i for i, e in enumerate(self.experiments) if e.magnet == 'fixed']
            poses = [fixed.index(i) if i in fixed else None for i in range(len(experiments))]
        self.poses = tuple(poses)
        count = len(vector.base.sensors)
        self._channels = [e.channels(count) for e in self.experiments]
        self.evaluations = 0

    # ------------------------------------------------------------------ model
    def values(self, z: np.ndarray) -> dict[str, float]:
        """Parameter values of the scaled free vector ``z`` (theta = nominal + scale z).

        Parameters
        ----------
        z : array_like, shape (free,)
            Scaled free parameters.
        """
        return self.vector.values(self.center + self.scale * np.asarray(z))

    def model(self, values: dict[str, float]) -> MaggyModel:
        """Return the fast model of a parameter vector's values.

        Parameters
        ----------
        values : dict
            Parameter values by name, SI.
        """
        return MaggyModel(self.vector.apply(values))

    def features(self, values: dict[str, float]) -> list[np.ndarray]:
        """Affine features ``[c; M]`` (n_s + 1, 3 k) per experiment.

        Parameters
        ----------
        values : dict
            Parameter values by name, SI.
        """
        model = self.model(values)
        self.evaluations += 1
        out = []
        for i, e in enumerate(self.experiments):
            if e.magnet == 'fixed':
                x = self.vector.pose(self.poses[i], values)
                present = True
            else:
                x, present = _ABSENT_STATE, False
            rows = np.array([model.measurement(x, u, with_magnet=present) for u in self._units])
            rows[1:] -= rows[0]
            out.append(rows[:, self._channels[i]])
        return out

    def predict(self, values: dict[str, float], exp: StaticExperiment, index: int, delay: int):
        """Predicted readings of ``exp`` (the ``index``-th experiment), shape (N - delay, 3 k).

        Parameters
        ----------
        values : dict
            Parameter values by name, SI.
        exp : StaticExperiment
            The record.
        index : int
            Its position in the problem.
        delay : int
            Sensor delay, samples.
        """
        theta = self.features(values)[index]
        u, _ = _shifted(exp, delay)
        return _regressors(u) @ theta

    # ------------------------------------------------------------------ criterion
    def residual(self, z: np.ndarray) -> np.ndarray:
        """Weighted reduced residual vector (length experiments x (n_s + 1) x 3 k).

        Parameters
        ----------
        z : array_like, shape (free,)
            Scaled free parameters.
        """
        feats = self.features(self.values(z))
        return np.concatenate(
            [
                ((s.root @ (f - s.theta_hat)) / s.sigma).ravel()
                for f, s in zip(feats, self.stats, strict=True)
            ]
        )

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """Return d residual / d z by central differences of the features (scaled units).

        Parameters
        ----------
        z : array_like, shape (free,)
            Scaled free parameters.
        """
        z = np.asarray(z, dtype=float)
        cols = []
        step = 1e-3
        for p in range(z.size):
            zp, zm = z.copy(), z.copy()
            zp[p] += step
            zm[p] -= step
            fp = self.features(self.values(zp))
            fm = self.features(self.values(zm))
            cols.append(
                np.concatenate(
                    [
                        ((s.root @ (a - b)) / (2 * step) / s.sigma).ravel()
                        for a, b, s in zip(fp, fm, self.stats, strict=True)
                    ]
                )
            )
        if not cols:
            return np.zeros((self.residual_size, 0))
        return np.column_stack(cols)

    @property
    def residual_size(self) -> int:
        """Length of the reduced residual vector."""
        return sum(s.theta_hat.size for s in self.stats)

    def chi2(self, z: np.ndarray) -> float:
        """Weighted sum of squares over every sample and channel (not just the reduced part).

        Parameters
        ----------
        z : array_like, shape (free,)
            Scaled free parameters.
        """
        r = self.residual(z)
        floor = sum(float(np.sum(s.residual_ss / s.sigma**2)) for s in self.stats)
        return floor + float(r @ r)

    @property
    def observations(self) -> int:
        """Number of scalar readings used."""
        return sum(s.samples * s.theta_hat.shape[1] for s in self.stats)


@dataclass(frozen=True)
class StaticCalibration:
    """Result of a static calibration.

    Attributes
    ----------
    vector : ParameterVector
        The parameters as set up (free flags, nominal values, bounds).
    names : tuple of str
        Estimated parameters (the free ones the data identify), in order.
    estimate : dict
        Every parameter's value after calibration (SI), by name; fixed and
        unidentified ones at their nominal value.
    std : dict
        Standard deviation of each estimated parameter, SI.
    correlation : ndarray, shape (len(names), len(names))
        Correlation matrix of the estimates.
    identifiability : Identifiability
        Which free parameters the data do not identify (held at nominal), and why.
    correlated : tuple of (str, str, float)
        Pairs of estimates with |correlation| > 0.95.
    params : MaggyParameters
        The calibrated parameter set (for :func:`~maglev_ros.greybox.write_parameters`).
    delays : tuple of int
        Sensor delay per experiment, samples.
    validation_nominal, validation_calibrated : tuple of ValidationFit
        Fits on each experiment's validation part.
    sensors : tuple of tuple of int
        Sensors recorded in each experiment (the channels of ``noise`` and the fits).
    noise : tuple of ndarray
        Noise level per experiment and channel, T rms.
    chi2_per_dof : float
        Weighted residual sum of squares per degree of freedom (about 1 when
        the model explains the data down to the noise).
    evaluations : int
        Model evaluations (features at one parameter vector).
    seconds : float
        Wall time of the fit, s.
    message : str
        The optimiser's termination message.
    delay_costs : tuple of tuple of float
        Per record, the prediction error for each tried sensor delay (empty
        when the delays were given): equal costs mean an undetermined delay.
    """

    vector: ParameterVector
    names: tuple[str, ...]
    estimate: dict
    std: dict
    correlation: np.ndarray
    identifiability: Identifiability
    correlated: tuple
    params: MaggyParameters
    delays: tuple[int, ...]
    validation_nominal: tuple[ValidationFit, ...]
    validation_calibrated: tuple[ValidationFit, ...]
    sensors: tuple
    noise: tuple
    chi2_per_dof: float
    evaluations: int
    seconds: float
    message: str = ''
    predictions: dict = field(default_factory=dict, repr=False)
    delay_costs: tuple = ()

    def table(self) -> list[str]:
        """Return the estimates as text lines (name, nominal, estimate, std, change/std)."""
        lines = [
            f'{"parameter":<28}{"nominal":>16} {"estimate":>16} {"std":>16} {"change/std":>11}'
        ]
        for name in self.names:
            spec = self.vector[name]
            est, sd = self.estimate[name], self.std[name]
            ratio = (est - spec.nominal) / sd if sd > 0 else np.inf
            lines.append(
                f'{name:<28}{spec.display(spec.nominal):>16} {spec.display(est):>16} '
                f'{spec.display(sd):>16} {ratio:>11.1f}'
            )
        return lines


def _default_pose(vector: ParameterVector) -> tuple[float, ...]:
    from ..physics.equilibria import find_equilibria

    found = find_equilibria(MaggyModel(vector.apply({})))
    if not found:
        raise GreyBoxError(
            'the nominal set has no equilibrium: give the held magnet pose (x, y, z, alpha, beta)'
        )
    return (0.0, 0.0, float(found[0].z), 0.0, 0.0)


def calibrate_static(
    vector: ParameterVector,
    experiments: Sequence[StaticExperiment],
    split: float = 0.5,
    delays: Sequence[int] | None = None,
    fit_pose: bool = True,
    progress: Callable[[str], None] | None = None,
    jacobian: str = 'features',
    frozen_run: int = 3,
) -> StaticCalibration:
    """Estimate the free parameters of ``vector`` from static experiments.

    Parameters
    ----------
    vector : ParameterVector
        Parameters; the free ones are estimated.
    experiments : sequence of StaticExperiment
        Records with the magnet absent or held fixed (each split into
        estimation and validation parts).
    split : float
        Fraction of each experiment used for estimation (the rest validates).
    delays : sequence of int, optional
        Sensor delay per experiment, samples (default: estimated, :func:`best_delay`).
    fit_pose : bool
        Estimate where each fixed magnet is held (x, y, z, alpha, beta).
    progress : callable, optional
        Called with a line of text at each stage and iteration.
    jacobian : {'features', '2-point'}
        ``features``: central differences of the affine features (default);
        ``2-point``: scipy's own finite differences of the residual (for comparison).
    frozen_run : int
        Leave out the readings of a frozen sensor: runs of at least this many
        identical readings (:meth:`StaticExperiment.frozen`); 0 keeps every reading.

    Returns
    -------
    StaticCalibration

    Raises
    ------
    GreyBoxError
        No experiment, no free parameter, bad split, too few samples or
        currents that do not excite every coil.
    """
    say = progress or (lambda _line: None)
    if not experiments:
        raise GreyBoxError('static calibration needs at least one experiment')
    if not 0.0 < split <= 1.0:
        raise GreyBoxError(f'split must be in (0, 1], got {split!r}')
    n_s = vector.base.solenoids.count
    count = len(vector.base.sensors)
    for e in experiments:
        n_y = 3 * (count if e.sensors is None else len(e.sensors))
        if e.sensors is not None and not all(0 <= k < count for k in e.sensors):
            raise GreyBoxError(
                f'{e.name}: sensors {list(e.sensors)} out of range: {vector.base.name} has '
                f'{count} sensors (0 to {count - 1})'
            )
        if e.u.shape[1] != n_s or e.y.shape[1] != n_y:
            raise GreyBoxError(
                f'{e.name}: {vector.base.name} has {n_s} coils and {n_y // 3} sensors '
                f'({n_y} field channels) here; the data have {e.u.shape[1]} currents and '
                f'{e.y.shape[1]} field channels'
            )
    fixed = [i for i, e in enumerate(experiments) if e.magnet == 'fixed']
    for count, i in enumerate(fixed):
        if f'pose{count}.x' not in vector:
            pose = experiments[i].pose or _default_pose(vector)
            vector = vector.with_pose(count, pose, free=fit_pose)
    if not vector.free_names:
        raise GreyBoxError('no free parameter: choose some with --free')
    costs: tuple = ()
    if delays is None:
        costs = tuple(delay_costs(e) for e in experiments)
        delays = [_first_best(c) for c in costs]
        for e, d in zip(experiments, delays, strict=True):
            say(f'{e.name}: sensor delay {d} sample(s) (best affine fit)')
    delays = tuple(int(d) for d in delays)
    if frozen_run:
        checked = []
        for e, d in zip(experiments, delays, strict=True):
            frozen = e.frozen(frozen_run, d)
            if frozen.any():
                say(f'{e.name}: {int(frozen.sum())} readings of a frozen sensor left out')
                keep = ~frozen if e.valid is None else e.valid & ~frozen
                e = dataclasses.replace(e, valid=keep)
            checked.append(e)
        experiments = checked
    parts = [e.split(split) if split < 1.0 else (e, e) for e in experiments]
    estimation = [p[0] for p in parts]
    validation = [p[1] for p in parts]

    start = time.perf_counter()
    problem = StaticProblem(vector, estimation, delays)
    fit = identified(problem, vector, lambda v: StaticProblem(v, estimation, delays), say)
    problem, vector_fit, keep, ident = fit.problem, fit.vector, fit.keep, fit.identifiability
    say(
        f'fitting {len(keep)} parameters to {problem.observations} readings '
        f'({sum(s.samples for s in problem.stats)} samples)'
    )
    solution = fit_bounded(
        problem,
        jacobian == 'features',
        1e-12,
        200,
        lambda k, r: say(f'iteration {k}: weighted cost {0.5 * float(r @ r):.6g}'),
    )
    z = solution.x
    values = problem.values(z)
    dof = max(problem.observations - len(keep), 1)
    s2 = problem.chi2(z) / dof
    fitted = spread(problem, problem.jacobian(z), s2)
    names, std, corr = fitted.names, fitted.std, fitted.correlation
    seconds = time.perf_counter() - start
    say(f'done in {seconds:.2f} s: {solution.message}')

    nominal_values = vector.nominal
    fits_nom, fits_cal, predictions = [], [], {}
    for i, (e, d) in enumerate(zip(validation, delays, strict=True)):
        check = StaticProblem(vector_fit, [e], [d], [problem.poses[i]])
        _, y = _shifted(e, d)
        for values_set, sink, label in (
            (nominal_values, fits_nom, 'nominal'),
            (values, fits_cal, 'calibrated'),
        ):
            yhat = check.predict(values_set, e, 0, d)
            err = y - yhat
            sink.append(ValidationFit(e.name, fit_percent(y, yhat), np.sqrt(np.mean(err**2, 0))))
            predictions[(i, label)] = yhat
        predictions[(i, 'measured')] = y
    return StaticCalibration(
        vector=vector,
        names=names,
        estimate=values,
        std=std,
        correlation=corr,
        identifiability=ident,
        correlated=correlated_pairs(names, corr, 0.95),
        params=vector_fit.apply(values),
        delays=delays,
        validation_nominal=tuple(fits_nom),
        validation_calibrated=tuple(fits_cal),
        sensors=tuple(
            tuple(range(count)) if e.sensors is None else e.sensors for e in experiments
        ),
        noise=tuple(s.sigma for s in problem.stats),
        chi2_per_dof=s2,
        evaluations=problem.evaluations,
        seconds=seconds,
        message=str(solution.message),
        predictions=predictions,
        delay_costs=costs,
    )
