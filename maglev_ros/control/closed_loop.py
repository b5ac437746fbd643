"""The closed loop without ROS: simulator -> estimator -> controller, sample by sample.

The very objects the nodes use (:class:`~maglev_ros.physics.Simulator`, an
:class:`~maglev_ros.estimation.Estimator`, an :class:`LqrController` or
:class:`PdController`) are stepped in the order of the lockstep graph: the
simulator's sample k (readings, one sample old on the board, and the coil
currents) goes to the estimator, its estimate to the controller, and the
command drives the coils from sample k + ``command_delay``. The controller
gets the estimate as the nodes carry it (``maglev/state/estimate``, an
Odometry: :func:`~maglev_ros.physics.kernels.odometry_round_trip`), so a
lockstep graph of the nodes steps to the same numbers.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..estimation.base import nis_band
from .config import MAX_COMMAND_DELAY
from .pd import PdController

__all__ = ['ClosedLoop', 'LoopResult', 'make_closed_loop', 'moving_rms']


def moving_rms(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing moving RMS over ``window`` samples, shape like ``values`` (first ones partial).

    Parameters
    ----------
    values : array_like, shape (N, ...)
        Samples.
    window : int
        Samples per window.
    """
    v = np.asarray(values, dtype=float)
    sq = np.concatenate([np.zeros((1,) + v.shape[1:]), np.cumsum(v**2, axis=0)])
    idx = np.arange(1, v.shape[0] + 1)
    lo = np.maximum(idx - window, 0)
    counts = (idx - lo).reshape((-1,) + (1,) * (v.ndim - 1))
    return np.sqrt(np.maximum(sq[idx] - sq[lo], 0.0) / counts)


@dataclass(frozen=True)
class LoopResult:
    """A closed-loop run (arrays per sample, N samples).

    Attributes
    ----------
    t : ndarray, shape (N,)
        s.
    x : ndarray, shape (N, 12)
        True state at each sample.
    estimate : ndarray, shape (N, 12)
        Estimate published at each sample (NaN while the estimator's input is cut).
    std : ndarray, shape (N, 10)
        Its standard deviations (reduced states).
    nis, dof : ndarray, shape (N,)
        NIS of the accepted readings and its degrees of freedom.
    command : ndarray, shape (N, n_s)
        Controller output at each sample, A.
    currents : ndarray, shape (N, n_s)
        Coil currents at each sample, A.
    reference : ndarray, shape (N, 3)
        Set-point, m.
    level : ndarray of str, shape (N,)
        Controller status level per sample.
    frozen : ndarray of bool, shape (N, k)
        Sensors the estimator held frozen at each sample.
    z_eq : float
        Equilibrium height of the *plant*, m (the hold metrics use it).
    crashed : bool
    reason : str
    messages : tuple of str
        Distinct ERROR/WARN messages of the controller, and the frozen
        sensors' names as the estimator's diagnostics gave them, in order.
    wall_time : float
        s spent in the loop.
    readings : ndarray, shape (N, 3 k)
        Sensor readings available at each sample (what the estimator or the
        PD was given, whether or not cut), T.
    """

    t: np.ndarray
    x: np.ndarray
    estimate: np.ndarray
    std: np.ndarray
    nis: np.ndarray
    dof: np.ndarray
    command: np.ndarray
    currents: np.ndarray
    reference: np.ndarray
    level: np.ndarray
    frozen: np.ndarray
    z_eq: float
    crashed: bool
    reason: str
    messages: tuple = field(default=())
    wall_time: float = 0.0
    readings: np.ndarray | None = field(default=None, repr=False)

    @property
    def dt(self) -> float:
        """Sample period, s."""
        return float(self.t[1] - self.t[0]) if self.t.size > 1 else 0.0

    def position_error(self, against_reference: bool = False) -> np.ndarray:
        """x, y, z - z_eq (or minus the reference), m, shape (N, 3).

        Parameters
        ----------
        against_reference : bool
            Subtract the reference instead of the equilibrium.
        """
        if against_reference:
            return self.x[:, :3] - self.reference
        err = self.x[:, :3].copy()
        err[:, 2] -= self.z_eq
        return err

    def settle_time(self, threshold: float = 1e-4, window: float = 0.1) -> float:
        """Return the first time every axis' ``window``-s moving RMS is below ``threshold``.

        Returns inf when it never is.

        Parameters
        ----------
        threshold : float
            RMS bound, m.
        window : float
            Window, s.
        """
        n = max(1, int(round(window / self.dt)))
        rms = moving_rms(self.position_error(), n)
        ok = np.all(rms < threshold, axis=1)
        ok[: n - 1] = False  # a full window first
        hits = np.flatnonzero(ok)
        return float(self.t[hits[0]]) if hits.size else float('inf')

    def hold(self, start: float) -> tuple[np.ndarray, np.ndarray]:
        """RMS and largest excursion per axis from ``start`` (s) on, m, shapes (3,), (3,).

        Parameters
        ----------
        start : float
            s.
        """
        err = self.position_error()[self.t >= start]
        return np.sqrt(np.mean(err**2, axis=0)), np.max(np.abs(err), axis=0)

    def consistency(self, start: float) -> np.ndarray:
        """Fraction of samples from ``start`` with |estimate - true| <= 3 sigma, for x, y, z.

        Parameters
        ----------
        start : float
            s.
        """
        sel = (self.t >= start) & np.all(np.isfinite(self.estimate), axis=1)
        err = np.abs(self.estimate[sel, :3] - self.x[sel, :3])
        return np.mean(err <= 3.0 * self.std[sel, :3], axis=0)

    def nis_windows(self, start: float, window: int = 500) -> tuple[np.ndarray, np.ndarray]:
        """Windowed NIS sums from ``start`` and whether each lies in its 99 % band.

        Parameters
        ----------
        start : float
            s.
        window : int
            Samples per window.

        Returns
        -------
        sums : ndarray, shape (W,)
        inside : ndarray of bool, shape (W,)
        """
        sel = np.flatnonzero(self.t >= start)
        w = len(sel) // window
        nis = self.nis[sel[: w * window]].reshape(w, window).sum(axis=1)
        dof = self.dof[sel[: w * window]].reshape(w, window).sum(axis=1)
        inside = np.empty(w, dtype=bool)
        cache: dict[int, tuple[float, float]] = {}
        for j in range(w):
            d = int(dof[j])
            if d not in cache:
                cache[d] = nis_band(d) if d else (0.0, 0.0)
            inside[j] = cache[d][0] <= nis[j] <= cache[d][1]
        return nis, inside

    def nis_average(self, start: float) -> tuple[float, tuple[float, float]]:
        """NIS summed from ``start`` on and its 99 % band (the time-averaged NIS test).

        Parameters
        ----------
        start : float
            s.
        """
        sel = self.t >= start
        total = float(self.nis[sel].sum())
        return total, nis_band(int(self.dof[sel].sum()))


class ClosedLoop:
    """Simulator -> estimator -> controller, stepped as in the lockstep graph.

    A :class:`~maglev_ros.loop.ControlLoop` on a
    :class:`~maglev_ros.loop.SimulatedPlant`, with an observer that keeps
    every sample as the arrays of a :class:`LoopResult`.

    Parameters
    ----------
    simulator : Simulator
        The plant (its own model: it may differ from the estimator's).
    estimator : Estimator or None
        None with a PD controller (it reads the raw field).
    controller : LqrController or PdController
    command_delay : int, optional
        Samples before a command drives the coils (default: the controller's
        ``command_delay``; 1 is the board: the command computed from sample k
        is applied from k+1; at most ``MAX_COMMAND_DELAY``).
    average, offset : int, optional
        Simulator steps per sample (each sample their readings' mean) and
        where in a group a new command lands
        (:class:`~maglev_ros.loop.SimulatedPlant`).
    """

    def __init__(
        self,
        simulator,
        estimator,
        controller,
        command_delay: int | None = None,
        average: int = 1,
        offset: int = 0,
    ):
        self.average, self.offset = average, offset
        self.simulator = simulator
        self.estimator = estimator
        self.controller = controller
        self.pd = isinstance(controller, PdController)
        if estimator is None and not self.pd:
            raise ValueError('the LQR needs an estimator')
        delay = controller.config.command_delay if command_delay is None else command_delay
        if isinstance(delay, bool) or delay not in range(MAX_COMMAND_DELAY + 1):
            raise ValueError(
                f'command_delay must be an integer from 0 to {MAX_COMMAND_DELAY}, got {delay!r}'
            )
        self.command_delay = delay
        from ..physics.equilibria import find_equilibria

        found = find_equilibria(simulator.model)
        self.z_eq = found[0].z if found else float('nan')

    def run(
        self,
        duration: float,
        x0=None,
        reference=None,
        cut: tuple[float, float] | None = None,
        progress=None,
        excitation=None,
    ) -> LoopResult:
        """Run for ``duration`` s of simulated time from ``x0`` (stops at a crash).

        Parameters
        ----------
        duration : float
            s.
        x0 : array_like, shape (12,), optional
            Initial true state (default: the plant's equilibrium). The
            estimator starts at its own equilibrium.
        reference : callable or None
            ``reference(t) -> position (3,) m or None``, evaluated each sample;
            a change calls the controller's ``set_reference``.
        cut : (start, length) in s, optional
            The estimator's input (the sample) is cut over this interval: no
            estimate reaches the controller (PD: no sample).
        progress : callable, optional
            ``progress(t)`` called about every simulated second.
        excitation : array_like, shape (N, n_s), optional
            Currents added to the controller's command at each sample, A, as
            an input disturbance (identification experiments; rows past its
            end add nothing, nor does a controller that commands zero:
            disabled, stale input or magnet lost); ``command`` in the result
            is the controller's own part. The controller node adds the same
            (:class:`~maglev_ros.control.excitation.ExcitationSchedule`).
        """
        from ..loop import ControlLoop, SimulatedPlant

        sim = self.simulator
        dt = sim.dt * self.average
        n = int(round(duration / dt))
        plant = SimulatedPlant(sim, cut=cut, average=self.average, offset=self.offset)
        plant.reset(x0)
        log = _ArrayLog(n, sim.model.n_inputs, sim.model.n_outputs, self.estimator)
        log.controller = None if self.pd else self.controller
        observers = [log]
        if progress is not None:
            every = int(round(1.0 / dt))
            observers.append(lambda s: s.index % every == 0 and s.index and progress(s.t))
        loop = ControlLoop(
            plant,
            self.controller,
            self.estimator,
            command_delay=self.command_delay,
            excitation=excitation,
            reference=reference,
            observers=observers,
        )
        wall = time.perf_counter()
        loop.run(n)
        wall = time.perf_counter() - wall
        return log.result(self.z_eq, sim.crashed, loop.reason if sim.crashed else '', wall)


class _ArrayLog:
    """A loop observer keeping every sample as arrays, and the distinct status messages."""

    def __init__(self, n: int, n_s: int, n_y: int, estimator) -> None:
        self.estimator = estimator
        self.done = 0
        self.t = np.arange(n) / 1.0
        self.x = np.full((n, 12), np.nan)
        self.estimate = np.full((n, 12), np.nan)
        self.std = np.full((n, 10), np.nan)
        self.nis = np.zeros(n)
        self.dof = np.zeros(n, dtype=np.int64)
        self.command = np.zeros((n, n_s))
        self.currents = np.zeros((n, n_s))
        self.reference = np.zeros((n, 3))
        self.level = np.empty(n, dtype=object)
        self.frozen = np.zeros((n, n_y // 3), dtype=bool)
        self.readings = np.full((n, n_y), np.nan)
        self.messages: list[str] = []
        self.controller = None  # the LQR, whose set-point is logged (NaN with the PD)

    def __call__(self, s) -> None:
        k = self.done
        self.done += 1
        self.t[k] = s.t
        self.x[k] = s.state
        self.currents[k] = s.currents
        self.readings[k] = s.reading
        self.command[k] = s.command
        self.level[k] = s.level
        self.reference[k] = np.nan if self.controller is None else self.controller.reference
        if s.estimate is not None:
            self.estimate[k] = s.estimate
            self.std[k] = s.std
            self.nis[k] = s.nis
            self.dof[k] = s.dof
            self.frozen[k] = s.frozen
            if s.frozen.any():
                names = ', '.join(self.estimator.status().frozen_names())
                if not self.messages or not self.messages[-1].startswith(
                    f'estimator: frozen {names}'
                ):
                    self.messages.append(f'estimator: frozen {names} at t = {s.t:.4f} s')
        if s.level != 'OK' and (s.level == 'ERROR' or k > 0):
            text = f'controller {s.level}: {s.message}'
            if not self.messages or self.messages[-1] != text:
                self.messages.append(text)

    def result(self, z_eq: float, crashed: bool, reason: str, wall: float) -> LoopResult:
        n = self.done
        return LoopResult(
            t=self.t[:n],
            x=self.x[:n],
            estimate=self.estimate[:n],
            std=self.std[:n],
            nis=self.nis[:n],
            dof=self.dof[:n],
            command=self.command[:n],
            currents=self.currents[:n],
            reference=self.reference[:n],
            level=self.level[:n],
            frozen=self.frozen[:n],
            z_eq=z_eq,
            crashed=crashed,
            reason=reason,
            messages=tuple(self.messages),
            wall_time=wall,
            readings=self.readings[:n],
        )


def make_closed_loop(
    params='maggy_v2',
    estimator=None,
    controller=None,
    plant=None,
    noise: float = 1.0e-4,
    quantization: float = 0.098e-3,
    sensor_delay: int = 1,
    coil_dynamics: bool = True,
    freeze=None,
    seed: int | None = 0,
    linear=None,
    average: int = 1,
    offset: int = 0,
) -> ClosedLoop:
    """Build the issue's simulated set-up: noisy, delayed sensors, coil electrics.

    Parameters
    ----------
    params : str, MaggyParameters or MaggyModel
        What the estimator and the controller believe (fast field, true
        torque, rigid kinematics unless a model is given).
    estimator : EstimatorConfig, optional
        Default: the KF.
    controller : ControllerConfig, optional
        Default: the LQR (``mode='pd'`` needs no estimator).
    plant : MaggyParameters or MaggyModel, optional
        The simulated plant when it differs from ``params`` (model mismatch).
    noise, quantization : float
        Sensor noise (T rms per axis) and resolution (T per LSB).
    sensor_delay : int
        Samples of sensor delay.
    coil_dynamics : bool
        Coil electrics (L / R, supply) on.
    freeze : SensorFreeze, optional
        Sensor freezes to inject.
    seed : int or None
        Noise (and random freeze) seed.
    linear : LinearModel, optional
        Linearisation of the believed model, to share.
    average : int
        Readings per sample: the simulator runs at ``average`` times the
        controller's rate and each sample is the mean of its readings (the
        estimator's config should say the same ``average``).
    offset : int
        Readings of each group before a new command applies (0 .. average-1).
    """
    from ..estimation import EstimatorConfig, make_estimator
    from ..physics import CoilDynamics, MaggyModel, SensorEffects, Simulator, linearize, make_model
    from . import ControllerConfig, make_controller

    model = params if isinstance(params, MaggyModel) else make_model(params)
    if plant is None:
        plant_model = model.with_options()
    elif isinstance(plant, MaggyModel):
        plant_model = plant
    else:
        plant_model = make_model(plant)
    controller = controller or ControllerConfig()
    lin = linear if linear is not None else linearize(model)
    rate = controller.sample_rate
    sim = Simulator(
        plant_model,
        rate * average,
        coil=CoilDynamics.from_parameters(plant_model.params) if coil_dynamics else None,
        sensor=SensorEffects(noise, quantization, 0.0, sensor_delay),
        seed=seed,
        freeze=freeze,
    )
    est = None
    if controller.mode == 'lqr':
        config = estimator or EstimatorConfig(sample_rate=rate, sensor_delay=sensor_delay)
        est = make_estimator(model, config, linear=lin)
    ctrl = make_controller(model, controller, linear=lin)
    return ClosedLoop(sim, est, ctrl, average=average, offset=offset)
