"""Settings of the magnet's state estimator (a frozen dataclass a node builds from parameters)."""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..parameters import NodeParameterError, check_settings, choice, integer, number, setting

__all__ = ['FILTERS', 'MEASUREMENTS', 'PREDICTIONS', 'EstimatorConfig', 'EstimatorConfigError']

#: Filter kinds: linear KF about the equilibrium, EKF and UKF on the nonlinear model.
FILTERS = ('kf', 'ekf', 'ukf')
#: Process models of the EKF and UKF prediction.
PREDICTIONS = ('fast', 'full')
#: What the readings are: the sensors' field, or a V4x PC-control board's processed field.
MEASUREMENTS = ('raw', 'board')


class EstimatorConfigError(ValueError):
    """A setting of :class:`EstimatorConfig` is out of range."""


def _zero_or_one(name: str, value: int) -> int:
    if isinstance(value, bool) or value not in (0, 1):
        raise NodeParameterError(f'{name} must be 0 or 1, got {value!r}')
    return value


def _gate(name: str, value: float) -> float:
    if not (0.5 < value <= 1.0):
        raise NodeParameterError(f'{name} must be in (0.5, 1], got {value!r}')
    return value


_zero_or_one.rule = '0 or 1'
_gate.rule = '(0.5, 1]'


@dataclass(frozen=True)
class EstimatorConfig:
    """Estimator settings. Units SI; defaults for the board (5 kHz, TLV493D).

    Attributes
    ----------
    filter : {'kf', 'ekf', 'ukf'}
        ``kf``: linear Kalman filter on the reduced 10-state model about the
        equilibrium (exact ZOH discretisation, compiled). ``ekf``: extended KF
        on the nonlinear model f, h (compiled finite-difference Jacobians).
        ``ukf``: unscented KF on f, h (filterpy's ``UnscentedKalmanFilter``
        equations, compiled).
    prediction : {'fast', 'full'}
        Process model of the EKF's and UKF's prediction. ``fast``: one
        exponential-Euler step of f per sample (per sigma point), with the
        Jacobian refreshed one column per sample (EKF) or from the sigma
        points (UKF): what runs in a 5 kHz loop, within 0.1 sigma of
        ``full`` (``benchmarks/estimator.py``). ``full``: one RK4 step of f
        (the simulator's integrator) and the whole Jacobian every sample.
    sample_rate : float
        Samples per second, Hz.
    sensor_delay : int
        Samples between a reading's instant and its arrival (0 or 1; the board
        has 1). With 1 the reading arriving at sample k is an update at k-1,
        then the filter predicts to k with the measured currents of k-1.
    sensor_noise : float
        Hall noise, T rms per axis.
    quantization : float
        Hall resolution, T per LSB (adds ``q^2 / 12`` to the noise variance).
    current_noise : float
        Uncertainty of the current held over a sample, A rms per coil (covers
        the ZOH of the measured current while the coil current ramps, and
        current-sense noise).
    acceleration_noise : float
        Unmodelled horizontal force per mass (vx, vy), m/s^2 rms held over
        each sample.
    vertical_acceleration_noise : float
        Unmodelled vertical force per mass (vz), m/s^2 rms held over each
        sample. Apart from the horizontal one: in the simulated lab the model's
        error is a few coil currents' error seen through B (the
        ``current_noise``) and a slow vertical drift (the KF's linearisation),
        not independent horizontal forces; a filter tuned so is consistent
        (``benchmarks/estimator_consistency.py``, the ``matched`` tuning).
    angular_acceleration_noise : float
        Unmodelled torque per inertia, rad/s^2 rms held over each sample.
        The default (50) covers the tilt mode's uncertainty: its stiffness
        (the base magnets' torque per inertia, 8,000 s^-2 on V2, 24,000 s^-2
        on V4) scales with the magnet's polarisation and inertia, and with a
        trusted model (0.5) the KF left that mode nearly undamped (its poles
        0.2 s^-1 inside the stability limit), so a 10 % weaker tilt mode made
        the loop unstable (V2, lost at 6 s); with 50 the loop's slowest
        oscillation decays at 4.4-8.1 s^-1 for +-10 % polarisation and mass
        (``benchmarks/mismatch_margins.py``) and the nominal hold is unchanged.
    bias_states : bool
        Estimate a constant offset per sensor axis (9 random-walk states);
        False assumes a calibrated board (offsets removed by the driver).
    bias_walk : float
        Random walk of the bias states, T rms per sample.
    initial_bias : float
        Initial standard deviation of the z bias states, T.
    initial_bias_xy : float
        Initial standard deviation of the x and y bias states (and of the
        board's filter states, which hold x and y), T. A bias of 1 mT on x
        or y reads as a displacement of about 5 mm (the field's gradient
        under the magnet is about 0.22 mT/mm): at start-up the filter takes
        the first readings' noise partly for such a bias and its position
        estimate leaves the magnet's (``maglev_ros.loop.v4x_pc_setup`` starts
        from 0.1 mT, where the board removes its own baseline).
    magnet_strength : bool
        Estimate the levitating magnet's strength (its polarisation relative to
        the parameter set's) as one state ``s``: the magnet's own field at the
        sensors is ``(1 + s)`` times the model's, ``y = y_base + (1 + s)
        y_magnet(x) + D u`` (bilinear: the update uses its Jacobian). KF only.
        One state, not nine: with 5 position and tilt states it is observable
        from the readings alone, where nine bias states let a static tilt pass
        for a sensor offset.
    initial_strength : float
        Initial standard deviation of ``s`` (relative).
    strength_walk : float
        Random walk of ``s``, relative, rms per sample.
    measurement : {'raw', 'board'}
        What the readings are. ``raw``: the sensors' field, as the physics
        model gives it. ``board``: the field a V4x PC-control firmware
        reports (:mod:`maglev_ros.physics.board_processing`): the power-up
        baseline (magnet absent, coils off) and the coils' feedthrough on x
        and y removed, x and y low-pass filtered (``f = 0.2 b + 0.8 f`` per
        200 us board step, so ``a = 0.8^(Ts / 200 us)`` per sample). The
        filter's state (one per filtered channel) joins the estimator's
        states, after the bias states. KF only; chosen, never inferred.
    average : int
        Readings per sample: each sample is the mean of this many readings
        taken at ``average`` times ``sample_rate`` (the simulator's
        ``average``; :mod:`maglev_ros.estimation.group_mean`). The filter's
        state is then at the group's start, the reading its exact linear
        function ``C_bar x + D_bar u`` with the sample's currents (the group's
        mean) held over the group, the noise variance divided by ``average``;
        the published estimate is the prediction to the group's end, the
        sample's stamp. ``sensor_delay`` (1) counts readings, not samples.
        KF with raw readings only; 1: single readings.
    gate_probability : float
        Per-sensor chi-square gate: a sensor's 3-axis innovation is rejected
        when its NIS exceeds the chi-square(3) quantile of this probability.
    freeze_samples : int
        A sensor whose reading (all three axes) has been identical this many
        samples in a row is frozen: its readings are treated as missing until
        it changes (the firmware resets a sensor after 20 identical samples).
    nis_window : int
        Samples in the diagnostics' NIS window.
    lost_samples : int
        No reading accepted (all missing, frozen or gated out) for this many
        samples in a row: the estimate is worthless (the x and y modes grow
        e-fold in 18-34 ms) and its covariance would grow without bound (after
        a lost magnet the gate rejects every reading), so the filter restarts
        from its prior at the equilibrium and counts a restart (default 500:
        0.1 s at 5 kHz).
    initial_position, initial_angle, initial_velocity, initial_rate : float
        Initial standard deviations: m, rad, m/s, rad/s.
    """

    filter: str = setting('kf', 'kf (linear, default), ekf or ukf', choice(*FILTERS))
    prediction: str = setting(
        'fast',
        'EKF/UKF process model: fast (one step per sample) or full (RK4)',
        choice(*PREDICTIONS),
    )
    sample_rate: float = setting(5000.0, 'samples per second, Hz', number(0, above=True))
    sensor_delay: int = setting(1, 'samples of reading delay (the board: 1)', _zero_or_one)
    sensor_noise: float = setting(1.0e-4, 'Hall noise, T rms per axis', number(0, above=True))
    quantization: float = setting(0.098e-3, 'Hall resolution, T per LSB', number(0))
    current_noise: float = setting(0.003, 'current held over a sample, A rms', number(0))
    acceleration_noise: float = setting(
        0.1, 'unmodelled horizontal force per mass, m/s^2 rms', number(0)
    )
    vertical_acceleration_noise: float = setting(
        0.1, 'unmodelled vertical force per mass, m/s^2 rms', number(0)
    )
    angular_acceleration_noise: float = setting(
        50.0, 'unmodelled torque per inertia, rad/s^2 rms', number(0)
    )
    bias_states: bool = setting(False, 'estimate a field offset per sensor axis')
    bias_walk: float = setting(
        1.0e-8, 'random walk of the bias states, T rms per sample', number(0)
    )
    initial_bias: float = setting(
        1.0e-3, 'initial std of the z bias states, T', number(0, above=True)
    )
    initial_bias_xy: float = setting(
        1.0e-3,
        "initial std of the x and y bias states (and the board's filter states), T",
        number(0, above=True),
    )
    magnet_strength: bool = setting(False, "estimate the magnet's strength as one state (kf only)")
    initial_strength: float = setting(
        0.2, 'initial std of the strength state, relative', number(0, above=True)
    )
    strength_walk: float = setting(
        1.0e-7, 'random walk of the strength state, relative rms per sample', number(0)
    )
    measurement: str = setting(
        'raw',
        "what the readings are: raw (the sensors) or board (a V4x PC-control board's "
        'processed field; kf only)',
        choice(*MEASUREMENTS),
    )
    average: int = setting(
        1,
        'readings per sample: each sample the mean of this many readings taken at average x '
        'sample_rate (kf, raw readings, sensor_delay 1; 1: single readings)',
        integer(1),
    )
    gate_probability: float = setting(0.99999, 'per-sensor chi-square gate probability', _gate)
    freeze_samples: int = setting(
        4, 'identical readings in a row that mark a sensor frozen', integer(2)
    )
    nis_window: int = setting(500, 'samples of the diagnostics NIS window', integer(2))
    lost_samples: int = setting(
        500,
        'samples without an accepted reading before the filter restarts from its prior',
        integer(2),
    )
    initial_position: float = setting(1.0e-3, 'initial position std, m', number(0, above=True))
    initial_angle: float = setting(0.03, 'initial angle std, rad', number(0, above=True))
    initial_velocity: float = setting(0.02, 'initial velocity std, m/s', number(0, above=True))
    initial_rate: float = setting(2.0, 'initial body-rate std, rad/s', number(0, above=True))

    def __post_init__(self):
        check_settings(self, EstimatorConfigError)
        if self.measurement == 'board' and (self.filter != 'kf' or self.magnet_strength):
            raise EstimatorConfigError(
                'measurement board is supported by the kf filter without magnet_strength only, '
                f'got filter {self.filter!r}, magnet_strength {self.magnet_strength!r}'
            )
        if self.average > 1 and (
            self.filter != 'kf'
            or self.measurement != 'raw'
            or self.magnet_strength
            or self.sensor_delay != 1
        ):
            raise EstimatorConfigError(
                f'average {self.average} (a mean of readings per sample) is supported by the kf '
                'filter with raw readings, sensor_delay 1 and without magnet_strength only, got '
                f'filter {self.filter!r}, measurement {self.measurement!r}, sensor_delay '
                f'{self.sensor_delay!r}, magnet_strength {self.magnet_strength!r}; set average 1 '
                'or filter kf'
            )
        if self.magnet_strength and self.filter != 'kf':
            raise EstimatorConfigError(
                f'magnet_strength is supported by the kf filter only, got filter {self.filter!r}'
            )

    @classmethod
    def from_mapping(cls, values: dict) -> EstimatorConfig:
        """Build from a mapping (e.g. ROS parameters), naming unknown keys.

        Parameters
        ----------
        values : dict
            Setting name to value.

        Raises
        ------
        EstimatorConfigError
            On an unknown key or a bad value.
        """
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise EstimatorConfigError(
                f'unknown estimator setting(s) {", ".join(unknown)}; '
                f'known: {", ".join(sorted(known))}'
            )
        return cls(**values)

    @property
    def dt(self) -> float:
        """Sample period, s."""
        return 1.0 / self.sample_rate

    @property
    def measurement_variance(self) -> float:
        """Variance per axis of a sample, T^2: noise plus uniform quantisation error.

        Of one reading, divided by ``average`` (the sample is their mean).
        """
        return (self.sensor_noise**2 + self.quantization**2 / 12.0) / self.average
