"""Nonlinear grey-box calibration by closed-loop simulation (as ``nlgreyest``, made stable).

``nlgreyest`` simulates the full model with the recorded inputs and fits the
simulated outputs to the measured ones (output error). The levitating magnet
is open-loop unstable, so the recorded coil currents fed to the nonlinear
model make the simulation diverge within tens of milliseconds. Here the
simulated system is the *closed loop*: the nonlinear plant of the parameters
``theta`` (:class:`~maglev_ros.physics.Simulator`: the full model, coil
electrics, sensor delay, no noise) held by the very estimator and controller
that ran during the experiment (known: their parameter set and configuration),
driven by the recorded excitation (what was added to the command)::

    y_sim(theta) = ClosedLoop(plant(theta), estimator, controller).run(excitation)
    minimise sum |(y_sim(theta) - y) / sigma|^2

The excitation is independent of the sensor noise, so this output error is
consistent although the noise also moved the magnet during the experiment
(that motion is left in the residual: coloured, which makes the standard
deviations below optimistic by the residual's correlation length). A loop
under a large mismatch is sensitive: the simulated trajectory drifts from the
recorded one, and the estimates are far less precise than the linear
grey-box's (:func:`~maglev_ros.greybox.calibrate_dynamic`). The Jacobian is by
forward differences of whole simulations.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..physics.parameters import MaggyParameters
from .errors import GreyBoxError
from .parameters import ParameterVector
from .predictor import LevitationExperiment, noise_level

__all__ = ['LoopSetup', 'ClosedLoopFit', 'calibrate_closed_loop']


@dataclass(frozen=True)
class LoopSetup:
    """What held the magnet during a levitation experiment.

    Attributes
    ----------
    believed : MaggyParameters
        The parameter set the estimator and the controller used.
    excitation : ndarray, shape (N, n_s)
        Currents added to the command at each sample, A.
    controller : ControllerConfig or None
        Its configuration (None: the defaults).
    estimator : EstimatorConfig or None
        Its configuration (None: the KF defaults).
    sensor_delay : int
        Samples of sensor delay.
    """

    believed: MaggyParameters
    excitation: np.ndarray = field(repr=False)
    controller: object | None = None
    estimator: object | None = None
    sensor_delay: int = 1


@dataclass(frozen=True)
class ClosedLoopFit:
    """Result of :func:`calibrate_closed_loop`.

    Attributes
    ----------
    names : tuple of str
    estimate : dict
        Every parameter's value (SI).
    std : dict
        Standard deviation of each estimate (optimistic, see the module).
    correlation : ndarray
    params : MaggyParameters
        The calibrated set.
    rms_nominal, rms_calibrated : float
        RMS of simulated minus measured field, T.
    simulations : int
    seconds : float
    message : str
    """

    names: tuple
    estimate: dict
    std: dict
    correlation: np.ndarray
    params: MaggyParameters
    rms_nominal: float
    rms_calibrated: float
    simulations: int
    seconds: float
    message: str = ''


def calibrate_closed_loop(
    vector: ParameterVector,
    experiment: LevitationExperiment,
    setup: LoopSetup,
    progress: Callable[[str], None] | None = None,
    start: dict | None = None,
) -> ClosedLoopFit:
    """Estimate the free parameters by simulating the closed loop with the known controller.

    Parameters
    ----------
    vector : ParameterVector
        Parameters; the free ones are estimated.
    experiment : LevitationExperiment
        The record (it must start when the loop started, magnet at rest).
    setup : LoopSetup
        The estimator and controller that ran, and the excitation.
    progress : callable, optional
        Called with a line of text per iteration.
    start : dict, optional
        Initial values of free parameters (default nominal; e.g. the linear
        grey-box estimate).

    Returns
    -------
    ClosedLoopFit

    Raises
    ------
    GreyBoxError
        No free parameter or an excitation that does not match the record.
    """
    from ..control.closed_loop import make_closed_loop
    from ..physics import linearize, make_model

    say = progress or (lambda _line: None)
    free = vector.free_specs
    if not free:
        raise GreyBoxError('no free parameter: choose some with --free')
    exc = np.asarray(setup.excitation, dtype=float)
    if exc.shape != experiment.u.shape:
        raise GreyBoxError(
            f'{experiment.name}: the excitation must have the currents shape '
            f'{experiment.u.shape}, got {exc.shape}'
        )
    believed = make_model(setup.believed)
    linear = linearize(believed)
    duration = experiment.samples * experiment.Ts
    channels = experiment.channels(len(vector.base.sensors))
    sigma = noise_level(experiment.y)
    scale = np.array([s.scale for s in free])
    center = np.array([s.nominal for s in free])
    count = [0]

    def simulate(values: dict) -> np.ndarray:
        count[0] += 1
        loop = make_closed_loop(
            believed,
            estimator=setup.estimator,
            controller=setup.controller,
            plant=vector.apply(values),
            noise=0.0,
            quantization=0.0,
            sensor_delay=setup.sensor_delay,
            linear=linear,
        )
        result = loop.run(duration, excitation=exc)
        y = np.full(experiment.y.shape, 1.0)  # a crash: large residual
        y[: result.readings.shape[0]] = result.readings[:, channels]
        return y

    def residual(z):
        values = vector.values(center + scale * np.asarray(z))
        return ((simulate(values) - experiment.y) / sigma).ravel()

    t0 = time.perf_counter()
    r_nominal = residual(np.zeros(len(free)))
    z0 = np.zeros(len(free))
    if start:
        z0 = np.array(
            [
                (start.get(spec.name, c) - c) / d
                for spec, c, d in zip(free, center, scale, strict=True)
            ]
        )
    iteration = [0]

    def jac(z):
        iteration[0] += 1
        r = residual(z)
        say(f'iteration {iteration[0]}: weighted cost per reading {float(r @ r) / r.size:.6g}')
        step = 1e-2
        cols = []
        for p in range(z.size):
            zp = np.array(z, dtype=float)
            zp[p] += step
            cols.append((residual(zp) - r) / step)
        return np.column_stack(cols)

    lower = np.array([(s.lower - s.nominal) / s.scale for s in free])
    upper = np.array([(s.upper - s.nominal) / s.scale for s in free])
    solution = least_squares(
        residual,
        z0,
        jac=jac,
        bounds=(lower, upper),
        method='trf',
        x_scale=1.0,
        ftol=1e-8,  # mass and polarisation correlate (~0.98): a loose ftol stops early
        xtol=1e-8,
        gtol=1e-8,
        max_nfev=20,
    )
    z = solution.x
    values = vector.values(center + scale * z)
    r = solution.fun
    jhat = solution.jac
    s2 = float(r @ r) / max(r.size - z.size, 1)
    cov = np.linalg.pinv(jhat.T @ jhat) * s2
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(divide='ignore', invalid='ignore'):
        corr = cov / np.outer(sd, sd)
    names = tuple(s.name for s in free)
    seconds = time.perf_counter() - t0
    say(f'done in {seconds:.2f} s ({count[0]} closed-loop simulations): {solution.message}')

    def rms(res):
        return float(np.sqrt(np.mean((res.reshape(experiment.y.shape) * sigma) ** 2)))

    return ClosedLoopFit(
        names=names,
        estimate=values,
        std={n: float(d * s.scale) for n, d, s in zip(names, sd, free, strict=True)},
        correlation=corr,
        params=vector.apply(values),
        rms_nominal=rms(r_nominal),
        rms_calibrated=rms(r),
        simulations=count[0],
        seconds=seconds,
        message=str(solution.message),
    )
