"""Dynamic calibration from levitation data: a linear grey-box fitted by prediction error.

While the magnet levitates under feedback (with an excitation added to the
command), the coil currents ``u`` (inputs) and the fields ``y`` (outputs) are
recorded. The grey-box model is the physics model linearised at the
equilibrium of the parameter set ``theta`` (as MATLAB's ``idgrey``: the
matrices are functions of the parameters)::

    A, B, C, D, y_eq = linearize(MaggyModel(theta)).reduced()      (10 states)
    Ad, Bd = zoh(A, B, Ts)                                          (exact ZOH)
    x_{k+1} = Ad x_k + Bd u_k + w_k
    y_{k+d} = y_eq + C x_k + D u_k + e_k                            (d: sensor delay)

The plant is open-loop unstable, so the output-error simulation of this model
diverges and the data are closed-loop: the one-step predictor is the
steady-state Kalman predictor in innovation form (``greyest`` with the ``'K'``
disturbance model)::

    eps_k = y_{k+d} - y_eq - C xh_k - D u_k
    xh_{k+1} = Ad xh_k + Bd u_k + K eps_k

with ``K`` the stationary Kalman gain of ``(Ad, C)`` (discrete Riccati
equation) for measurement noise ``R = diag(sigma^2)`` (``sigma``: each
channel's noise level, from the data) and a small input-disturbance process
noise ``Q = Bd Bd^T q^2`` (``q`` A rms). So ``K`` is a function of ``theta``
too, not a block of free parameters: the simulated plant has no process
noise, its true predictor is the Kalman one with ``q -> 0``; a real board's
unmeasured disturbances are what ``q`` stands for. The free parameters
minimise ``sum |eps_k / sigma|^2`` (scipy's ``least_squares``, Jacobian by
central differences of the predictor); standard deviations from the Jacobian
at the optimum in the sandwich form with a Newey-West long-run variance of
the scores (:mod:`.uncertainty`): the prediction errors are correlated in
time, and the white-noise formula would understate the spread.  Added in
quadrature: how far the optimum moves when the linearisation's
finite-difference step is ten times larger (along a flat, correlated
direction the model's numerical noise moves the optimum by several
statistical standard deviations).

The currents come from the coil drivers, measured at the samples; the ZOH
assumes them constant over a sample.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .bounded_fit import fit_bounded, identified
from .errors import GreyBoxError
from .identifiability import correlated_pairs
from .parameters import ParameterVector
from .predictor import LevitationExperiment, LinearGreyBoxProblem, noise_level
from .static import StaticCalibration, ValidationFit, fit_percent
from .uncertainty import long_run_spread

__all__ = [
    'MIN_ESTIMATION',
    'DynamicCalibration',
    'calibrate_dynamic',
]

#: Fewest estimation samples per record (split x samples).
MIN_ESTIMATION = 1000


@dataclass(frozen=True)
class DynamicCalibration(StaticCalibration):
    """Result of a dynamic calibration (the fields of :class:`StaticCalibration`, and these).

    ``validation_*`` and ``predictions`` hold one-step-ahead predictions of
    the validation part (Kalman predictor of each parameter set).

    Attributes
    ----------
    form : str
        ``linear`` (grey-box prediction error) or ``nonlinear``.
    process_noise : float
        Kalman gain's input-disturbance level, A rms.
    z_eq : tuple of float
        Equilibrium height of the nominal and the calibrated set, m.
    notes : tuple of str
        What went wrong on the way (a diverging nonlinear predictor).
    std_white : dict
        Standard deviations if the prediction errors were white (``s^2 (J^T J)^-1``);
        ``std`` is the sandwich (Newey-West) one, :mod:`.uncertainty`.
    hac_lags : int
        Lag window of the Newey-West long-run variance, samples.
    std_numerical : dict
        How far the optimum moves when the model's linearisation is computed
        with a ten times larger finite-difference step (refit from the
        optimum): the numerical part of the uncertainty, in ``std`` in quadrature.
    """

    form: str = 'linear'
    process_noise: float = 0.0
    z_eq: tuple = ()
    notes: tuple = ()
    std_white: dict | None = None
    hac_lags: int = 0
    std_numerical: dict | None = None


def calibrate_dynamic(
    vector: ParameterVector,
    experiments: Sequence[LevitationExperiment],
    split: float = 0.5,
    delay: int | None = None,
    process_noise: float = 1e-3,
    progress: Callable[[str], None] | None = None,
    jacobian: str = 'central',
    max_delay: int = 3,
    form: str = 'linear',
    measurement: str = 'raw',
    board_pairs=None,
    fit_board_pairs: bool = True,
) -> DynamicCalibration:
    """Estimate the free parameters of ``vector`` from levitation data (linear grey-box).

    Parameters
    ----------
    vector : ParameterVector
        Parameters; the free ones are estimated (the magnet's mass and
        polarisation, which static data cannot give, and others).
    experiments : sequence of LevitationExperiment
        Levitation records (each split into estimation and validation parts).
    split : float
        Fraction of each record used for estimation.
    delay : int, optional
        Sensor delay, samples (default: the one in 0..``max_delay`` with the
        smallest nominal prediction error).
    process_noise : float
        Kalman gain's input-disturbance level, A rms.
    progress : callable, optional
        Called with a line of text at each stage and iteration.
    jacobian : {'central', '2-point'}
        ``central``: central differences of the predictor (default);
        ``2-point``: scipy's own forward differences (for comparison).
    max_delay : int
        Largest delay tried.
    form : {'linear', 'nonlinear'}
        ``linear``: the linearised model's Kalman predictor (``idgrey``);
        ``nonlinear``: the full model's predictor with the same gain
        (``nlgreyest``-like, :mod:`~maglev_ros.greybox.nonlinear`).
    measurement : {'raw', 'board'}
        What the field channels are: the raw field, or a V4x PC-control
        firmware's output (baseline and feedthrough removed, x/y low-pass;
        chosen by the user, never inferred). Linear form only.
    board_pairs : array_like, shape (3 k, 2), optional
        ``board``: the processed field per ampere of each coil pair, measured
        without the magnet, T/A (:class:`LinearGreyBoxProblem`); default: the
        firmware's compensation taken as exact.
    fit_board_pairs : bool
        ``board``, one sensor: estimate what each axis's own coil pair leaves
        in its readings (``board.bx_xpair``, ``board.by_ypair``, from
        ``board_pairs`` or the model's exact compensation) along with the
        free parameters. A few 0.01 mT/A there move the magnet's polarisation
        and mass by several of their standard deviations along the line
        they share; estimated, that uncertainty is in their standard
        deviations.

    Returns
    -------
    DynamicCalibration

    Raises
    ------
    GreyBoxError
        No experiment, no free parameter, bad split, mismatched records, or
        a nominal set without equilibrium.
    """
    say = progress or (lambda _line: None)
    if form == 'linear':
        problem_type = LinearGreyBoxProblem
    elif form == 'nonlinear':
        from .nonlinear import NonlinearGreyBoxProblem

        problem_type = NonlinearGreyBoxProblem
    else:
        raise GreyBoxError(f"form must be 'linear' or 'nonlinear', got {form!r}")
    if not experiments:
        raise GreyBoxError('dynamic calibration needs at least one levitation record')
    if not 0.0 < split <= 1.0:
        raise GreyBoxError(f'split must be in (0, 1], got {split!r}')
    if not (np.isfinite(process_noise) and process_noise > 0):
        raise GreyBoxError(f'process_noise must be positive, got {process_noise!r}')
    n_s = vector.base.solenoids.count
    count = len(vector.base.sensors)
    first = experiments[0]
    for e in experiments:
        n_y = 3 * (count if e.sensors is None else len(e.sensors))
        if e.sensors is not None and not all(0 <= k < count for k in e.sensors):
            raise GreyBoxError(
                f'{e.name}: sensors {list(e.sensors)} out of range: {vector.base.name} has '
                f'{count} sensors (0 to {count - 1})'
            )
        if e.u.shape[1] != n_s or e.y.shape[1] != n_y:
            raise GreyBoxError(
                f'{e.name}: {vector.base.name} has {n_s} coils and {n_y // 3} sensors here; '
                f'the data have {e.u.shape[1]} currents and {e.y.shape[1]} field channels'
            )
        if e.sensors != first.sensors or abs(e.Ts - first.Ts) > 1e-9 * first.Ts:
            raise GreyBoxError(f'{e.name}: every record needs the same sensors and sample time')
        if e.samples * split < MIN_ESTIMATION:
            need = int(np.ceil(MIN_ESTIMATION / split))
            raise GreyBoxError(
                f'{e.name}: {e.samples} samples are too few: they give '
                f'{int(e.samples * split)} for estimation; '
                f'dynamic calibration needs at least {MIN_ESTIMATION} estimation samples '
                f'(split {split:g} x samples), so {need} or more samples with --split '
                f'{split:g}: record longer or raise --split'
            )
    if not vector.free_names:
        raise GreyBoxError('no free parameter: choose some with --free')
    parts = [e.split(split) if split < 1.0 else (e, e) for e in experiments]
    estimation = [p[0] for p in parts]
    validation = [p[1] for p in parts]
    sigma = np.median([noise_level(e.y) for e in estimation], axis=0)
    board = {'measurement': measurement, 'board_pairs': board_pairs}
    channels = estimation[0].channels(len(vector.base.sensors))
    if measurement == 'board' and fit_board_pairs and channels.size == 3:
        from ..physics.board_processing import BoardProcessing
        from ..physics.model import MaggyModel

        start = board_pairs
        if start is None:
            start = BoardProcessing.model_pairs(MaggyModel(vector.base), channels[::3] // 3)
        vector = vector.with_board_pairs(start)
        say(
            "the board's pair feedthrough is estimated too (board.bx_xpair, board.by_ypair; "
            + ('from the measured values)' if board_pairs is not None else 'from zero)')
        )
    say(f'noise level per channel: {", ".join(f"{1e3 * s:.3f}" for s in sigma)} mT rms')

    start = time.perf_counter()
    costs: list[float] = []
    if delay is None:
        for d in range(max_delay + 1):
            # the linear predictor finds the same delay at a tenth of the cost
            trial = LinearGreyBoxProblem(vector, estimation, d, sigma, process_noise, **board)
            r = trial.residual(np.zeros(len(trial.free)))
            costs.append(float(r @ r) / r.size)
        delay = int(np.argmin(costs))
        say(
            f'sensor delay {delay} sample(s) (nominal prediction error per reading: '
            + ', '.join(f'{d}: {c:.3g}' for d, c in enumerate(costs))
            + ')'
        )
    if form == 'nonlinear' and measurement != 'raw':
        raise GreyBoxError(
            'the nonlinear form models the raw field only: use the linear form with '
            'the board measurement model'
        )
    extra = board if form == 'linear' else {}
    problem = problem_type(vector, estimation, delay, sigma, process_noise, **extra)
    if form == 'nonlinear':
        from .nonlinear import divergence_text

        problem.residual(np.zeros(len(problem.free)))
        if problem.diverged:
            raise GreyBoxError(
                f'{divergence_text(problem)} at the nominal parameters: nothing can be fitted; '
                'use --form linear, raise --process-noise, or check that the measurement '
                'model matches the board (--measurement)'
            )
    fit = identified(
        problem,
        vector,
        lambda v: problem_type(v, estimation, delay, sigma, process_noise, **extra),
        say,
    )
    problem, vector_fit, keep, ident = fit.problem, fit.vector, fit.keep, fit.identifiability
    say(
        f'fitting {len(keep)} parameters to {problem.residual_size} readings '
        f'({form} grey-box, Kalman predictor, delay {delay})'
    )
    solution = fit_bounded(
        problem,
        jacobian == 'central',
        1e-10,
        50,
        lambda k, r: say(f'iteration {k}: weighted cost per reading {float(r @ r) / r.size:.6g}'),
    )
    z = solution.x
    values = problem.values(z)
    r = problem.residual(z)
    dof = max(r.size - len(keep), 1)
    s2 = float(r @ r) / dof
    blocks = [e.samples - delay - problem.burn for e in estimation]
    fitted = long_run_spread(problem, problem.jacobian(z), r, blocks, problem.channels.size, s2)
    names, corr = fitted.spread.names, fitted.spread.correlation
    say(
        f'standard deviations from the sandwich covariance (Newey-West, {fitted.lags} lags): '
        + ', '.join(f'{n} x{fitted.inflation[n]:.2g}' for n in names)
        + ' the white-noise ones'
    )
    numerical = _numerical_spread(problem, z, say)
    std = {n: float(np.hypot(fitted.spread.std[n], numerical.get(n, 0.0))) for n in names}
    notes = []
    if solution.status == 0:
        notes.append(
            f'the fit stopped at its evaluation limit without converging ({solution.message}): '
            'the estimates wander along a flat direction of the cost; free fewer '
            'parameters or record with more excitation'
        )
    seconds = time.perf_counter() - start
    say(f'done in {seconds:.2f} s: {solution.message}')

    nominal_values = vector.nominal
    fits_nom, fits_cal, predictions = [], [], {}
    check = problem_type(vector_fit, validation, delay, sigma, process_noise, **extra)
    z_eq = []
    for label, values_set, sink in (
        ('nominal', nominal_values, fits_nom),
        ('calibrated', values, fits_cal),
    ):
        z_eq.append(check.system(values_set).z_eq)
        for i, (e, err) in enumerate(zip(validation, check.errors(values_set), strict=True)):
            y = e.y[delay:][check.burn :]
            yhat = y - err
            sink.append(ValidationFit(e.name, fit_percent(y, yhat), np.sqrt(np.mean(err**2, 0))))
            predictions[(i, label)] = yhat
            predictions[(i, 'measured')] = y
    return DynamicCalibration(
        vector=vector,
        names=names,
        estimate=values,
        std=std,
        correlation=corr,
        identifiability=ident,
        correlated=correlated_pairs(names, corr, 0.95),
        params=vector_fit.apply(values),
        delays=tuple(delay for _ in experiments),
        validation_nominal=tuple(fits_nom),
        validation_calibrated=tuple(fits_cal),
        sensors=tuple(
            tuple(range(count)) if e.sensors is None else e.sensors for e in experiments
        ),
        noise=tuple(sigma for _ in experiments),
        chi2_per_dof=s2,
        evaluations=problem.evaluations,
        seconds=seconds,
        message=str(solution.message),
        predictions=predictions,
        form=form,
        process_noise=float(process_noise),
        z_eq=tuple(z_eq),
        delay_costs=(tuple(costs),) if costs else (),
        std_white=dict(fitted.white.std),
        hac_lags=fitted.lags,
        notes=(*notes, *_divergence_notes(problem)),
        std_numerical=numerical,
    )


NUMERICAL_STEP_FACTOR = 10.0  # the numerical check's linearisation step, times the default


def _numerical_spread(problem, z: np.ndarray, say) -> dict[str, float]:
    """Return how far the optimum moves with a coarser linearisation step, per parameter.

    Along a flat direction of the cost (two strongly correlated parameters) the
    optimum is set by the model's numerical noise as much as by the data; the
    statistical standard deviations cannot see that, this refit does.
    """
    coarse = copy.copy(problem)
    coarse.fd_step = problem.fd_step * NUMERICAL_STEP_FACTOR
    coarse._last = coarse._last_jacobian = None
    lower = np.array([(s.lower - s.nominal) / s.scale for s in problem.free])
    upper = np.array([(s.upper - s.nominal) / s.scale for s in problem.free])
    try:
        again = least_squares(
            coarse.residual, np.clip(z, lower, upper), jac=lambda x: coarse.jacobian(x),
            bounds=(lower, upper), method='trf', x_scale=1.0, ftol=1e-10, xtol=1e-10,
            gtol=1e-10, max_nfev=20,
        )  # fmt: skip
    except (ValueError, np.linalg.LinAlgError):
        return {}
    moved = np.abs(again.x - z) * np.array([s.scale for s in problem.free])
    out = {s.name: float(m) for s, m in zip(problem.free, moved, strict=True)}
    say(
        'numerical check (linearisation step x10, refit): the optimum moves by '
        + ', '.join(f'{n} {problem.vector[n].display(v)}' for n, v in out.items())
    )
    return out


def _divergence_notes(problem) -> tuple[str, ...]:
    if not getattr(problem, 'divergences', None):
        return ()
    from .nonlinear import divergence_text

    return (divergence_text(problem) + ' during the fit',)
