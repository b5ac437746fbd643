"""Simulation of the Maggy model: fixed-step sampled simulator and a reference path.

:class:`Simulator` advances the model one sample at a time (zero-order hold
on the input, RK4 sub-steps), optionally through the coils' electrical
dynamics and with sensor effects (noise, quantisation, offset, one sample of
delay), all seeded. Touching the base or leaving the workspace ends the run
with a "crashed" status and the time and state where it happened; the
simulator never integrates through a crash and never returns NaNs.

:func:`simulate_reference` integrates the same model with scipy's
``solve_ivp`` at tight tolerances, for checking the fixed-step path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from . import kernels

__all__ = [
    'CoilDynamics',
    'SensorEffects',
    'SensorFreeze',
    'SimulationResult',
    'SimulationCrashedError',
    'Simulator',
    'simulate_reference',
    'CRASH_REASONS',
    'MAGNET_MODES',
]

MAGNET_MODES = ('free', 'fixed', 'absent')
_OK = kernels.STATUS_OK
_NOISE_BLOCK = 256  # samples of sensor noise drawn at once
CRASH_REASONS = {
    kernels.STATUS_CRASH_BASE: 'touched the base',
    kernels.STATUS_CRASH_WORKSPACE: 'left the workspace',
    kernels.STATUS_NOT_FINITE: 'state not finite',
}
_COIL_MODES = {
    'current': kernels.COIL_CURRENT_COMMAND,
    'voltage': kernels.COIL_VOLTAGE,
    'duty': kernels.COIL_DUTY,
}


class SimulationCrashedError(RuntimeError):
    """The simulation has crashed; reset it before stepping again."""


@dataclass(frozen=True)
class CoilDynamics:
    """First-order coil electrics ``L di/dt = V - R i`` with a saturating supply.

    Attributes
    ----------
    drive : {'current', 'voltage', 'duty'}
        Meaning of the input: ``current`` - a commanded current, applied as the
        voltage ``R i_cmd`` (what the board's open-loop driver does);
        ``voltage`` - volts; ``duty`` - PWM duty in [-1, 1] of the supply.
        The voltage is clipped at +-supply in every case.
    resistance : float
        Coil resistance, ohm.
    inductance : float
        Coil inductance, H.
    supply_voltage : float
        Supply, V.
    """

    drive: str = 'current'
    resistance: float = 3.0
    inductance: float = 0.004
    supply_voltage: float = 12.0

    def __post_init__(self):
        if self.drive not in _COIL_MODES:
            raise ValueError(f'drive must be one of {", ".join(_COIL_MODES)}, got {self.drive!r}')
        for name in ('resistance', 'inductance', 'supply_voltage'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f'{name} must be positive, got {value!r}')

    @classmethod
    def from_parameters(cls, params, drive: str = 'current') -> CoilDynamics:
        """Coil electrics of a parameter set's ``coils`` section.

        Parameters
        ----------
        params : MaggyParameters
            The parameter set.
        drive : str
            What the commands are: 'current' (default), 'voltage' or 'duty'.
        """
        c = params.coils
        return cls(drive, c.resistance, c.inductance, c.supply_voltage)


@dataclass(frozen=True)
class SensorEffects:
    """Imperfections of the Hall sensors, applied to h(x, u).

    Attributes
    ----------
    noise_rms : float
        White Gaussian noise per axis, T rms.
    quantization : float
        Step of the reading, T per LSB (0: none).
    offset : float or array_like, shape (3 k,)
        Added offset, T.
    delay_samples : int
        Samples of output delay (0 or more; the board has 1).
    """

    noise_rms: float = 0.0
    quantization: float = 0.0
    offset: float | tuple = 0.0
    delay_samples: int = 0

    def __post_init__(self):
        if not (np.isfinite(self.noise_rms) and self.noise_rms >= 0):
            raise ValueError(f'noise_rms must be >= 0, got {self.noise_rms!r}')
        if not (np.isfinite(self.quantization) and self.quantization >= 0):
            raise ValueError(f'quantization must be >= 0, got {self.quantization!r}')
        if not isinstance(self.delay_samples, (int, np.integer)) or self.delay_samples < 0:
            raise ValueError(f'delay_samples must be an integer >= 0, got {self.delay_samples!r}')


@dataclass(frozen=True)
class SensorFreeze:
    """Sensor freezes: a sensor repeats its last reading (all three axes).

    Under coil switching the TLE493D/TLV493D sometimes repeat one reading until
    they are reset; the board's firmware resets a sensor after 20 identical
    samples. Freezes are applied to the reading after noise and quantisation
    and before the output delay (the sensor itself repeats).

    Attributes
    ----------
    schedule : tuple of (int, float, float)
        Scheduled freezes ``(sensor index, start s, duration s)``: the sensor
        repeats the reading it gave just before ``start`` for the samples with
        ``start <= t < start + duration`` (the firmware's reset is not modelled
        for these: they are injected faults).
    rate : float
        Random freezes per second per sensor (seeded by the simulator's seed).
    length : int
        Samples a random freeze lasts (the firmware resets after 20 identical).
    """

    schedule: tuple = ()
    rate: float = 0.0
    length: int = 20

    def __post_init__(self):
        entries = []
        for entry in self.schedule:
            try:
                sensor, start, duration = entry
                entries.append((int(sensor), float(start), float(duration)))
            except (TypeError, ValueError):
                raise ValueError(
                    f'schedule entries must be (sensor, start s, duration s), got {entry!r}'
                ) from None
            if entries[-1][0] < 0 or not (entries[-1][2] > 0 and np.isfinite(entries[-1][1])):
                raise ValueError(
                    f'schedule entry needs sensor >= 0, finite start, duration > 0, got {entry!r}'
                )
        object.__setattr__(self, 'schedule', tuple(entries))
        if not (np.isfinite(self.rate) and self.rate >= 0):
            raise ValueError(f'rate must be >= 0, got {self.rate!r}')
        if not isinstance(self.length, (int, np.integer)) or self.length < 1:
            raise ValueError(f'length must be an integer >= 1, got {self.length!r}')

    @property
    def active(self) -> bool:
        """True when any freeze can happen."""
        return bool(self.schedule) or self.rate > 0


@dataclass
class SimulationResult:
    """A simulated run.

    Attributes
    ----------
    t : ndarray, shape (N + 1,)
        Sample times, s.
    x : ndarray, shape (N + 1, 12)
        States at the sample times.
    y : ndarray, shape (N + 1, 3 k)
        Sensor readings, T.
    u : ndarray, shape (N, n_s)
        Inputs applied over each sample (ZOH).
    currents : ndarray, shape (N + 1, n_s)
        Coil currents, A (equal to the inputs without coil dynamics).
    status : str
        ``ok`` or ``crashed``.
    reason : str
        Why it crashed (empty when ok).
    crash_time : float or None
        Time of the first sample where the crash was detected, s.
    crash_state : ndarray or None, shape (12,)
        State there (finite: the last finite state if the step blew up).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    u: np.ndarray
    currents: np.ndarray
    status: str = 'ok'
    reason: str = ''
    crash_time: float | None = None
    crash_state: np.ndarray | None = field(default=None, repr=False)

    @property
    def crashed(self) -> bool:
        """True when the run ended in a crash."""
        return self.status == 'crashed'


class Simulator:
    """Sampled simulation of a :class:`MaggyModel` (ZOH input, RK4 sub-steps).

    Parameters
    ----------
    model : MaggyModel
        The model (``fast`` runs compiled; other models run in Python).
    sample_rate : float
        Samples per second, Hz (the board: 5000).
    substeps : int
        RK4 steps per sample.
    coil : CoilDynamics or None
        Coil electrics; None makes the input the coil current directly.
    sensor : SensorEffects or None
        Sensor imperfections; None for ideal sensors.
    seed : int or None
        Seed of the sensor noise.
    check_crash : bool
        Detect touching the base and leaving the workspace.
    x0 : array_like, shape (12,), optional
        Initial state (default: resting at the first equilibrium).
    magnet : {'free', 'fixed', 'absent'}
        ``free``: the magnet moves (levitation). ``fixed``: held at ``x0``, only
        the coils evolve (identify the current-to-field path with the magnet in
        place). ``absent``: no levitating magnet at all (base and coils only).
    freeze : SensorFreeze or None
        Sensor freezes, scheduled or random (seeded with ``seed``).
    hold : float
        A free magnet is held at ``x0`` for this long after each (re)start, s,
        then released, as a hand holds the magnet while the loop comes up (the
        coils and sensors run meanwhile). 0: free from the start.
    """

    def __init__(
        self,
        model,
        sample_rate: float = 5000.0,
        substeps: int = 1,
        coil: CoilDynamics | None = None,
        sensor: SensorEffects | None = None,
        seed: int | None = None,
        check_crash: bool = True,
        x0=None,
        magnet: str = 'free',
        freeze: SensorFreeze | None = None,
        hold: float = 0.0,
    ):
        if magnet not in MAGNET_MODES:
            raise ValueError(f'magnet must be one of {", ".join(MAGNET_MODES)}, got {magnet!r}')
        self.magnet = magnet
        if not (math.isfinite(hold) and hold >= 0):
            raise ValueError(f'hold must be a finite number of seconds >= 0, got {hold!r}')
        if not (np.isfinite(sample_rate) and sample_rate > 0):
            raise ValueError(f'sample_rate must be positive, got {sample_rate!r}')
        if not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise ValueError(f'substeps must be an integer >= 1, got {substeps!r}')
        self.model = model
        self.sample_rate = float(sample_rate)
        self.dt = 1.0 / self.sample_rate
        self.substeps = int(substeps)
        #: samples a free magnet is held after each (re)start (0: none)
        self.hold_samples = int(round(hold * self.sample_rate)) if magnet == 'free' else 0
        self.coil = coil
        self.sensor = sensor or SensorEffects()
        self.seed = seed
        self.check_crash = bool(check_crash)
        p = model.params
        self._crash = np.concatenate(
            [
                [p.base_top, p.magnet.radius, p.magnet.thickness / 2],
                p.workspace.lower,
                p.workspace.upper,
            ]
        )
        if coil is None:
            self._coil_mode = kernels.COIL_IDEAL
            self._electrical = np.array([1.0, 1.0, 1.0])
        else:
            self._coil_mode = _COIL_MODES[coil.drive]
            self._electrical = np.array([coil.resistance, coil.inductance, coil.supply_voltage])
        offset = np.broadcast_to(np.asarray(self.sensor.offset, dtype=float), (model.n_outputs,))
        self._offset = np.array(offset, dtype=float)
        self._no_noise = np.zeros(self._offset.shape[0])
        self.freeze = freeze or SensorFreeze()
        n_sensors = model.n_outputs // 3
        for sensor, _, _ in self.freeze.schedule:
            if sensor >= n_sensors:
                raise ValueError(
                    f'freeze schedule names sensor {sensor}, the model has {n_sensors}'
                )
        self._ideal_sensor = (
            not self.freeze.active
            and self.sensor.noise_rms == 0
            and self.sensor.quantization == 0
            and not self.sensor.delay_samples
            and not np.any(self._offset)
        )
        self._default_x0 = None if x0 is None else self._check_state(x0)
        self._fast = model.options.field == 'fast'
        self._input_shape = (model.n_inputs,)
        if self._fast:
            self._fast_args = model.fast_arguments()
            sens, mag = model.measurement_arguments()[2:4]
            if magnet == 'absent':
                mag = np.array([mag[0], 0.0])  # no levitating magnet: its field is zero
            self._sens_args = (sens, mag)
            self._free_args, self._held_args = (
                (
                    kernels.simulator_config(
                        self.dt,
                        self.substeps,
                        self._coil_mode,
                        self.check_crash,
                        frozen,
                        self._electrical,
                        self._crash,
                    ),
                    *self._fast_args,
                    *self._sens_args,
                )
                for frozen in (magnet != 'free', True)
            )
            self._step_args = self._free_args
        self.reset()
        if self._fast:
            self._sample_step = _compiled(
                kernels.sample_step, self._xe, np.zeros(model.n_inputs), *self._step_args
            )

    # ------------------------------------------------------------------ state
    def reset(self, x0=None) -> np.ndarray:
        """Restart at ``x0`` (default: the constructor's, else the equilibrium).

        Parameters
        ----------
        x0 : array_like, shape (12,), optional
            Initial state.

        Returns
        -------
        ndarray, shape (3 k,)
            The first sensor reading.
        """
        if x0 is not None:
            state = self._check_state(x0)
        else:
            if self._default_x0 is None:  # found once, then reused by every reset
                self._default_x0 = self._equilibrium_state()
            state = self._default_x0
        n_s = self.model.n_inputs
        self._xe = np.concatenate([state, np.zeros(n_s)]) if self._coil_mode else state.copy()
        self.time = 0.0
        self.samples = 0
        self.status = 'ok'
        self.reason = ''
        self.crash_time: float | None = None
        self.crash_state: np.ndarray | None = None
        if self._fast:
            self._step_args = self._held_args if self.hold_samples else self._free_args
        self._seed_noise()
        self._reset_freeze()
        self._pending = []
        self._last_input = np.zeros(n_s)
        return self._observe(self._true_output())

    @property
    def held(self) -> bool:
        """True while a free magnet is still held (the first :attr:`hold_samples` samples)."""
        return self.samples < self.hold_samples

    @property
    def state(self) -> np.ndarray:
        """Current 12-state (copy)."""
        return self._xe[:12].copy()

    @property
    def currents(self) -> np.ndarray:
        """Coil currents now, A, shape (n_s,) (the last input without coil dynamics)."""
        if self._coil_mode:
            return self._xe[12:].copy()
        return self._last_input.copy()

    @property
    def crashed(self) -> bool:
        """True after a crash, until :meth:`reset`."""
        return self.status == 'crashed'

    # ------------------------------------------------------------------ stepping
    def step(self, u) -> np.ndarray:
        """Advance one sample with input ``u`` held (ZOH) and return the reading.

        Parameters
        ----------
        u : array_like, shape (n_s,)
            Input over this sample: coil currents (A), or the coil drive
            (commanded current A, voltage V or duty) with coil dynamics.

        Returns
        -------
        ndarray, shape (3 k,)
            Sensor reading at the end of the sample, T.

        Raises
        ------
        SimulationCrashedError
            When stepping a crashed simulation (reset it first).
        """
        if self.status != 'ok':
            raise SimulationCrashedError(
                f'simulation crashed at t = {self.crash_time:.6f} s ({self.reason}); '
                'reset it first'
            )
        drive = np.array(u, dtype=float)  # a copy: the caller may reuse its buffer
        if drive.shape != self._input_shape:
            raise ValueError(
                f'input must have {self._input_shape[0]} values (x+, x-, y+, y-), '
                f'got shape {drive.shape}'
            )
        if self._fast:
            new, status, y = self._sample_step(self._xe, drive, *self._step_args)
            if status == _OK:  # the hot path: 5000 calls a second, keep it lean
                self.samples += 1
                self.time = self.samples * self.dt
                self._xe = new
                self._last_input = drive
                if self.samples == self.hold_samples:  # released
                    self._step_args = self._free_args
                return y if self._ideal_sensor else self._observe(y)
            if status == kernels.STATUS_BAD_INPUT:
                raise ValueError(f'input must be finite, got {drive.tolist()}')
        else:
            if not math.isfinite(drive.sum()):
                raise ValueError(f'input must be finite, got {drive.tolist()}')
            new = self._python_rk4(self._xe, drive, self.held)
            status = self._status(new, self.held)
            y = None
        self.samples += 1
        self.time = self.samples * self.dt
        if status != kernels.STATUS_OK:
            self._mark_crash(status, new)
            return self._observe(self._true_output())
        self._xe = new
        self._last_input = drive
        return self._observe(self._true_output() if y is None else y)

    def run(self, inputs, x0=None, progress=None) -> SimulationResult:
        """Simulate a whole input sequence from ``x0`` (resets first).

        Parameters
        ----------
        inputs : array_like, shape (N, n_s)
            Input per sample (ZOH).
        x0 : array_like, shape (12,), optional
            Initial state.
        progress : callable, optional
            ``progress(done, total)`` as the work advances (the uncompiled
            accurate and filament models: integration steps, then sensor
            readings, ``total = 2 N + 1``; the compiled path reports once at the
            end).

        Returns
        -------
        SimulationResult
            Stops at the first crash (arrays then end at the last good sample).
        """
        drives = np.ascontiguousarray(np.asarray(inputs, dtype=float))
        n_s = self.model.n_inputs
        if drives.ndim != 2 or drives.shape[1] != n_s:
            raise ValueError(f'inputs must have shape (N, {n_s}), got {drives.shape}')
        if not np.all(np.isfinite(drives)):
            raise ValueError('inputs must be finite')
        self.reset(x0)
        total = 2 * len(drives) + 1
        if self._fast:
            states, truth, done, status, last = self._compiled_run(drives)
        else:
            states, done, status, last = self._python_run(drives, progress, total)
            truth = None
        currents = (
            states[:, 12:] if self._coil_mode else np.vstack([np.zeros((1, n_s)), drives[:done]])
        )
        if truth is None:
            truth = []
            for x, i in zip(states, currents, strict=True):
                truth.append(
                    self.model.measurement(x[:12], i, with_magnet=self.magnet != 'absent')
                )
                if progress is not None and len(truth) % 16 == 0:
                    progress(len(drives) + len(truth), total)
            truth = np.array(truth)
        if progress is not None:
            progress(total, total)
        self._seed_noise()
        self._reset_freeze()
        self._pending = []
        outputs = self._observe_many(truth)
        self._xe = states[-1].copy()
        self._last_input = drives[done - 1].copy() if done else np.zeros(n_s)
        self.samples = done
        self.time = done * self.dt
        if status != kernels.STATUS_OK:
            self.samples = done + 1
            self.time = self.samples * self.dt
            self._mark_crash(status, last)
        t = np.arange(done + 1) * self.dt
        return SimulationResult(
            t=t,
            x=states[:, :12].copy(),
            y=outputs,
            u=drives[:done].copy(),
            currents=np.array(currents),
            status=self.status,
            reason=self.reason,
            crash_time=self.crash_time,
            crash_state=self.crash_state,
        )

    # ------------------------------------------------------------------ internals
    def _rates(self, xe: np.ndarray, drive: np.ndarray, volts: np.ndarray) -> np.ndarray:
        if not self._coil_mode:
            return self.model.dynamics(xe, drive)
        i_coil = xe[12:]
        r, inductance = self._electrical[0], self._electrical[1]
        return np.concatenate(
            [self.model.dynamics(xe[:12], i_coil), (volts - r * i_coil) / inductance]
        )

    def _compiled_run(self, drives: np.ndarray):
        """:func:`kernels.rk4_run` over ``drives`` from the reset state, the hold first."""
        h = min(self.hold_samples, len(drives))
        if not h:
            return kernels.rk4_run(self._xe, drives, *self._free_args)
        held = kernels.rk4_run(self._xe, drives[:h], *self._held_args)
        if held[3] != kernels.STATUS_OK or h == len(drives):
            return held
        states, truth, done, status, last = kernels.rk4_run(
            held[0][-1].copy(), drives[h:], *self._free_args
        )
        return (
            np.concatenate([held[0], states[1:]]),
            np.concatenate([held[1], truth[1:]]),
            h + done,
            status,
            last,
        )

    def _python_rk4(self, xe: np.ndarray, drive: np.ndarray, held: bool = False) -> np.ndarray:
        if self.magnet != 'free' or held:
            return kernels.coil_step(xe, drive, self.dt, self._coil_mode, self._electrical)
        volts = kernels.coil_voltages(
            drive, self._coil_mode, self._electrical[0], self._electrical[2]
        )
        h = self.dt / self.substeps
        x = xe.copy()
        for _ in range(self.substeps):
            k1 = self._rates(x, drive, volts)
            k2 = self._rates(x + 0.5 * h * k1, drive, volts)
            k3 = self._rates(x + 0.5 * h * k2, drive, volts)
            k4 = self._rates(x + h * k3, drive, volts)
            x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        return x

    def _python_run(self, drives: np.ndarray, progress=None, total: int = 0):
        states = [self._xe.copy()]
        for k, drive in enumerate(drives):
            if progress is not None and k % 16 == 0:
                progress(k, total)
            held = k < self.hold_samples
            new = self._python_rk4(states[-1], drive, held)
            status = self._status(new, held)
            if status != kernels.STATUS_OK:
                return np.array(states), k, status, new
            states.append(new)
        return np.array(states), len(drives), kernels.STATUS_OK, states[-1]

    def _status(self, xe: np.ndarray, held: bool = False) -> int:
        if self.check_crash and self.magnet == 'free' and not held:
            c = self._crash
            return kernels.crash_status(xe[:12], c[0], c[1], c[2], c[3:6], c[6:9])
        return kernels.STATUS_OK if np.all(np.isfinite(xe)) else kernels.STATUS_NOT_FINITE

    def _mark_crash(self, status: int, attempted: np.ndarray) -> None:
        self.status = 'crashed'
        self.reason = CRASH_REASONS[status]
        self.crash_time = self.time
        finite = attempted[:12] if np.all(np.isfinite(attempted[:12])) else self._xe[:12]
        self.crash_state = finite.copy()

    def _true_output(self) -> np.ndarray:
        return self.model.measurement(
            self._xe[:12], self.currents, with_magnet=self.magnet != 'absent'
        )

    def observe(self, y) -> np.ndarray:
        """Return what the sensors read for the true field ``y`` (this simulator's effects).

        The offset, noise, quantisation, freeze and delay of the sensors, as
        :meth:`step` applies them, drawing from the same noise stream: e.g. the
        readings of a crashed magnet, which a real sensor still reads with its noise.

        Parameters
        ----------
        y : array_like, shape (3 k,)
            True fields, T.

        Returns
        -------
        ndarray, shape (3 k,)
            Readings, T.
        """
        return self._observe(np.asarray(y, dtype=float))

    def _observe(self, y: np.ndarray) -> np.ndarray:
        fx = self.sensor
        if self._ideal_sensor:
            return y
        noise = self._noise_row(y.shape[0]) if fx.noise_rms > 0 else self._no_noise
        reading = np.empty(y.shape[0])
        kernels.sensor_reading(y, self._offset, noise, fx.noise_rms, fx.quantization, reading)
        if self.freeze.active:
            reading = self._apply_freeze(reading)
        if fx.delay_samples:
            self._pending.append(reading)
            if len(self._pending) <= fx.delay_samples:
                return self._pending[0].copy()
            return self._pending.pop(0)
        return reading

    def _noise_row(self, n: int) -> np.ndarray:
        """Return the next sample's standard normal noise, shape (n,).

        Drawn a block of samples at a time: the same numbers, in the same
        order, as one ``standard_normal(n)`` per sample (numpy's Generator
        fills an array element by element from its stream).
        """
        block = self._noise_block
        if block is None or self._noise_next == block.shape[0] or block.shape[1] != n:
            block = self._noise_block = self._rng.standard_normal((_NOISE_BLOCK, n))
            self._noise_next = 0
        self._noise_next += 1
        return block[self._noise_next - 1]

    def _seed_noise(self) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._noise_block: np.ndarray | None = None
        self._noise_next = 0

    @property
    def frozen_sensors(self) -> tuple[int, ...]:
        """Indices of the sensors whose last reading was frozen (repeated)."""
        return tuple(int(k) for k in np.flatnonzero(self._frozen_now))

    def _reset_freeze(self) -> None:
        n_sensors = self.model.n_outputs // 3
        seed = None if self.seed is None else [int(self.seed), 1]
        self._freeze_rng = np.random.default_rng(seed)
        self._frozen_left = np.zeros(n_sensors, dtype=np.int64)  # random freezes
        self._frozen_now = np.zeros(n_sensors, dtype=bool)
        self._held = None
        self._observed = 0  # readings taken since reset (reading n is at t = n dt)

    def _apply_freeze(self, reading: np.ndarray) -> np.ndarray:
        """Replace the frozen sensors' readings by their last ones (before the delay)."""
        t = self._observed * self.dt
        self._observed += 1
        frozen = self._frozen_left > 0
        self._frozen_left[frozen] -= 1
        if self.freeze.rate > 0:
            starts = self._freeze_rng.random(frozen.size) < self.freeze.rate * self.dt
            starts &= ~frozen
            self._frozen_left[starts] = self.freeze.length - 1
            frozen |= starts
        eps = 1e-9 * self.dt  # sample times are n dt: keep the window's edges exact
        for sensor, start, duration in self.freeze.schedule:
            if start - eps <= t < start + duration - eps:
                frozen[sensor] = True
        if self._held is None:
            frozen[:] = False  # the very first reading has nothing to repeat
        out = reading.reshape(-1, 3).copy()
        if frozen.any():
            out[frozen] = self._held[frozen]
        self._held = out.copy()
        self._frozen_now = frozen
        return out.ravel()

    def _observe_many(self, truth: np.ndarray) -> np.ndarray:
        """Apply the sensor effects to a whole run's true readings (as :meth:`_observe`)."""
        if self._ideal_sensor:
            return truth.copy()
        return np.array([self._observe(y) for y in truth])

    def _check_state(self, x0) -> np.ndarray:
        state = np.asarray(x0, dtype=float)
        if state.shape != (12,) or not np.all(np.isfinite(state)):
            raise ValueError(f'x0 must be 12 finite numbers, got {x0!r}')
        return state.copy()

    def _equilibrium_state(self) -> np.ndarray:
        from .equilibria import rest_state

        return rest_state(self.model)


def _compiled(dispatcher, *example):
    """Return the compiled entry point of a numba function for the example's types.

    Calling it skips the dispatcher's per-call type resolution (about 0.5 us per
    call with ten arguments, 2-3 % of a simulator step). Falls back to the
    dispatcher itself if numba's internals differ.
    """
    try:
        import numba

        dispatcher.compile(tuple(numba.typeof(value) for value in example))
        signature = tuple(numba.typeof(value) for value in example)
        return dispatcher.overloads[signature].entry_point
    except Exception:  # noqa: BLE001 - an optimisation only
        return dispatcher


def simulate_reference(
    model,
    x0,
    inputs,
    sample_time: float,
    rtol: float = 1e-10,
    atol: float = 1e-13,
    check_crash: bool = True,
) -> SimulationResult:
    """Integrate the model with ``solve_ivp`` (DOP853) at tight tolerances.

    The input is held constant over each sample (ZOH) and the integration is
    restarted at every change of input, so the result is the exact solution of
    the sampled system up to the tolerances. Coil dynamics and sensor effects
    are not applied (ideal current input, true h(x, u)).

    Parameters
    ----------
    model : MaggyModel
    x0 : array_like, shape (12,)
        Initial state.
    inputs : array_like, shape (N, n_s)
        Coil currents per sample, A.
    sample_time : float
        Sample period, s.
    rtol, atol : float
        solve_ivp tolerances.
    check_crash : bool
        Stop at the first sample whose state has crashed.

    Returns
    -------
    SimulationResult
    """
    drives = np.asarray(inputs, dtype=float)
    state = np.asarray(x0, dtype=float).copy()
    p = model.params
    crash = (
        p.base_top,
        p.magnet.radius,
        p.magnet.thickness / 2,
        p.workspace.lower,
        p.workspace.upper,
    )
    states = [state]
    status = kernels.STATUS_OK
    k = 0
    n = drives.shape[0]
    while k < n:
        # merge consecutive samples with the same input into one segment
        end = k + 1
        while end < n and np.array_equal(drives[end], drives[k]):
            end += 1
        u = drives[k]
        t_eval = (np.arange(k + 1, end + 1) - k) * sample_time
        sol = solve_ivp(
            lambda _t, x, u=u: model.dynamics(x, u),
            (0.0, t_eval[-1]),
            states[-1],
            method='DOP853',
            t_eval=t_eval,
            rtol=rtol,
            atol=atol,
        )
        for column in sol.y.T:
            status = kernels.crash_status(column, *crash) if check_crash else kernels.STATUS_OK
            if status != kernels.STATUS_OK:
                break
            states.append(column)
        if status != kernels.STATUS_OK:
            break
        k = end
    x = np.array(states)
    done = len(states) - 1
    y = np.array(
        [
            model.measurement(xi, drives[i - 1] if i else np.zeros(model.n_inputs))
            for i, xi in enumerate(x)
        ]
    )
    result = SimulationResult(
        t=np.arange(done + 1) * sample_time,
        x=x,
        y=y,
        u=drives[:done].copy(),
        currents=np.vstack([np.zeros((1, model.n_inputs)), drives[:done]]),
    )
    if status != kernels.STATUS_OK:
        result.status = 'crashed'
        result.reason = CRASH_REASONS[status]
        result.crash_time = (done + 1) * sample_time
        result.crash_state = x[-1].copy()
    return result
