"""The identification workflow of ``maglev-sysid`` and ``maglev-lab``: fit, validate, keep all.

One call fits every requested model on the estimation data and validates it on
the validation data (``compare`` fit on both parts, residual analysis). Each
model gets its own :class:`ModelRow`, whatever happens to the others:

* ``ok``: stable, and its validation residuals pass (white, independent of
  past inputs), or every validation fit is at least :data:`NEGLIGIBLE_FIT`
  percent (noise-free or quantised data: the residuals are at the data's
  resolution; a note says the tests failed);
* ``reduced``: the model is unstable but its unstable poles cancel against
  zeros (orders above the data's, typical of ``iv4``): validated with the
  cancelling pairs removed (:mod:`~.cancellation`), residuals pass;
* ``unstable``: unstable (an open-loop-unstable plant identified from
  closed-loop data is), its k-step prediction is finite and its residuals pass:
  its simulation fits are NaN and it is judged on the k-step fit;
* ``whiteness failed``, ``independence failed``, ``whiteness and independence
  failed``: the residual test named failed (the reason says what to do);
* ``closed-loop bias``: the data were taken in closed loop and the method
  ignores the feedback (OE, IV with the input as instrument);
* ``diverges``: the simulation, the k-step predictor or the residual filter
  overflows;
* ``failed``: the estimator refused (too few samples, singular data, ...):
  NaN fits and the reason;
* ``no response``: an output that does not move (constant after detrending):
  nothing to identify.

Every fitted model, unstable ones included, also gets a k-step prediction fit
(:data:`KSTEP_HORIZON` samples unless ``--horizon`` chooses another).  The data
are tested for feedback first (:mod:`~.feedback`); in closed loop the residual
independence test skips lag 0.

Nothing raised by one model stops the others, and text LAPACK's Fortran
runtime might print goes into the row's reason instead of the terminal.
:attr:`Identification.exit_status` is 0 when every requested model is usable
(``ok``, ``reduced``, ``unstable``, ``no response``) and 1 otherwise.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .armax import armax
from .arx import arx
from .cancellation import cancelling_pairs, root_text, without_cancelling_pairs
from .dataset import IdData
from .feedback import FeedbackTest, detect_feedback
from .fortran_output import captured_fd_stdout
from .iv import iv4
from .model import PolyModel
from .oe_bj import bj, oe
from .orders import OrderError, make_orders
from .regression import check_data
from .validation import ResidualAnalysis, compare, resid

__all__ = [
    'KSTEP_HORIZON',
    'ORDER_NAMES',
    'DegenerateDataError',
    'Identification',
    'ModelRow',
    'ModelSpec',
    'check_channels',
    'constant_hints',
    'constant_inputs',
    'identify',
    'identify_outputs',
    'offset_hints',
]

ORDER_NAMES: dict[str, tuple[str, ...]] = {
    'arx': ('na', 'nb', 'nk'),
    'iv': ('na', 'nb', 'nk'),
    'armax': ('na', 'nb', 'nc', 'nk'),
    'oe': ('nb', 'nf', 'nk'),
    'bj': ('nb', 'nc', 'nd', 'nf', 'nk'),
}
USABLE = ('ok', 'reduced', 'unstable', 'no response')
#: Horizon in samples of the k-step prediction fit shown for every model.
KSTEP_HORIZON = 5
#: Validation fit (percent) above which failed residual tests do not count: the
#: residuals are then at the data's resolution (noise-free or quantised records).
NEGLIGIBLE_FIT = 99.9
OFFSET_RATIO = 0.5  # |mean| / std of a channel above which an offset hint is given


class DegenerateDataError(ValueError):
    """The data cannot identify anything (e.g. an output equal to an input)."""


@dataclass(frozen=True)
class ModelSpec:
    """One requested model: structure and orders.

    Attributes
    ----------
    structure : str
        ``'arx'``, ``'iv'`` (iv4), ``'armax'``, ``'oe'`` or ``'bj'``.
    orders : Mapping[str, Any]
        Orders by name (``na``, ``nb``, ``nc``, ``nd``, ``nf``, ``nk``): integers,
        or order matrices for MIMO models; ``nk`` defaults to 1.
    """

    structure: str
    orders: Mapping[str, Any]

    def __post_init__(self) -> None:
        if self.structure not in ORDER_NAMES:
            raise ValueError(
                f'unknown model structure {self.structure!r}: choose from {", ".join(ORDER_NAMES)}'
            )
        unknown = set(self.orders) - set(ORDER_NAMES[self.structure])
        if unknown:
            raise ValueError(f'{self.structure}: unknown orders {sorted(unknown)}')
        missing = set(ORDER_NAMES[self.structure]) - set(self.orders) - {'nk'}
        if missing:
            raise ValueError(f'{self.structure}: missing orders {sorted(missing)}')

    @property
    def label(self) -> str:
        """Name for tables and legends, e.g. ``ARX 7 9 1`` (``ARX`` for order matrices)."""
        values = [self.orders.get(k, 1) for k in ORDER_NAMES[self.structure]]
        head = 'IV4' if self.structure == 'iv' else self.structure.upper()
        if all(np.ndim(v) == 0 for v in values):
            return f'{head} {" ".join(str(int(v)) for v in values)}'
        return head

    def check(self, data: IdData) -> None:
        """Refuse orders that cannot be estimated on ``data`` (before anything is fitted).

        Parameters
        ----------
        data : IdData
            Estimation data.

        Raises
        ------
        ValueError
            Orders inconsistent with the channels (``OrderError``), a
            single-input structure on multi-channel data, or fewer samples than
            parameters; the message names the model.
        """
        o = dict(self.orders)
        if self.structure in ('oe', 'bj') and (data.ny, data.nu) != (1, 1):
            raise OrderError(
                f'{self.label}: OE and BJ are single-input single-output here; the data '
                f'have {data.ny} outputs and {data.nu} inputs'
            )
        try:
            if self.structure in ('oe', 'bj'):
                orders = make_orders(
                    1, 1, na=0, nb=o['nb'], nk=o.get('nk', 1), nc=o.get('nc', 0),
                    nd=o.get('nd', 0), nf=o['nf'],
                )  # fmt: skip
            else:
                orders = make_orders(
                    data.ny, data.nu, na=o['na'], nb=o['nb'], nk=o.get('nk', 1),
                    nc=o.get('nc', 0),
                )  # fmt: skip
            check_data([data], orders)
        except ValueError as err:
            raise type(err)(f'{self.label}: {err}') from None

    def fit(
        self,
        data: IdData,
        max_iter: int | None = None,
        progress: Callable[[int, float], None] | None = None,
        instruments: np.ndarray | None = None,
    ) -> PolyModel:
        """Estimate this model on ``data``.

        Parameters
        ----------
        data : IdData
            Estimation data.
        max_iter : int, optional
            Iteration cap of the prediction-error methods (ARMAX, OE, BJ;
            default theirs: 50, 100, 100).
        progress : callable, optional
            ``(step, loss)`` after every Levenberg-Marquardt step of ARMAX.
        instruments : ndarray, shape (N, nz), optional
            External instruments of IV (closed-loop data: the excitation),
            see :func:`~.iv.iv4`; ignored by the other structures.

        Returns
        -------
        PolyModel
            The estimate.
        """
        o = dict(self.orders)
        nk = o.get('nk', 1)
        extra: dict[str, Any] = {} if max_iter is None else {'max_iter': int(max_iter)}
        if self.structure == 'arx':
            return arx(data, o['na'], o['nb'], nk)
        if self.structure == 'iv':
            return iv4(data, o['na'], o['nb'], nk, instruments=instruments)
        if self.structure == 'armax':
            return armax(data, o['na'], o['nb'], o['nc'], nk, progress=progress, **extra)
        if self.structure == 'oe':
            return oe(data, o['nb'], o['nf'], nk, **extra)
        return bj(data, o['nb'], o['nc'], o['nd'], o['nf'], nk, **extra)


@dataclass(frozen=True)
class ModelRow:
    """The outcome of one requested model (see the module docstring for ``status``).

    Attributes
    ----------
    label : str
        Name of the model, e.g. ``ARX 7 9 1`` (with the output for per-output rows).
    structure : str
        Requested structure.
    status : str
        ``ok``, ``reduced``, ``unstable``, ``failed`` or ``no response``.
    reason : str
        Why the status is not ``ok`` (empty if it is).
    model : PolyModel or None
        The estimate (None if the estimator failed or nothing was fitted).
    validated : PolyModel or None
        The model the fits belong to: ``model``, or its reduction for ``reduced``.
    fit_estimation, fit_validation : ndarray, shape (ny,)
        ``compare`` fits in percent (NaN where they cannot be computed).
    prediction_fit : ndarray, shape (ny,)
        The estimator's one-step prediction fit on the estimation data (NaN if
        the estimator failed): the model-only figure kept for unstable models.
    residuals : ResidualAnalysis or None
        Residual analysis on the validation data.
    notes : tuple of str
        Further remarks: iteration cap reached, cancelling pole-zero pairs.
    outputs : tuple of str
        The output channels the row covers.
    kstep_estimation, kstep_validation : ndarray, shape (ny,)
        ``compare`` fits of the ``kstep``-step-ahead prediction in percent
        (computed for every fitted model, unstable ones included).
    kstep : int
        Their horizon in samples.
    """

    label: str
    structure: str
    status: str
    reason: str
    model: PolyModel | None
    validated: PolyModel | None
    fit_estimation: np.ndarray
    fit_validation: np.ndarray
    prediction_fit: np.ndarray
    residuals: ResidualAnalysis | None
    notes: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    kstep_estimation: np.ndarray = field(default_factory=lambda: np.full(1, np.nan))
    kstep_validation: np.ndarray = field(default_factory=lambda: np.full(1, np.nan))
    kstep: int = 0

    @property
    def usable(self) -> bool:
        """True for ``ok``, ``reduced``, ``unstable`` and ``no response`` rows."""
        return self.status in USABLE

    @property
    def residual_verdict(self) -> str:
        """``pass``, ``fail: whiteness``, ``fail: independence``, ... or ``-`` (none)."""
        if self.residuals is None:
            return '-'
        failed = self.residuals.failed_tests
        return 'pass' if not failed else 'fail: ' + ', '.join(failed)


@dataclass(frozen=True)
class Identification:
    """All rows of one identification run and the data they came from.

    Attributes
    ----------
    estimation, validation : IdData
        The two parts of the data (validation keeps the record's time axis).
    rows : tuple of ModelRow
        One row per requested model (per output for :func:`identify_outputs`).
    horizon : int or None
        Prediction horizon of the fits (None: simulation).
    ic : str
        Initial conditions of the fits.
    hints : tuple of str
        Advice about the data (e.g. offsets without detrending).
    feedback : FeedbackTest or None
        The closed-loop test of the estimation data (None if not run).
    kstep : int
        Horizon in samples of the rows' k-step fits.
    """

    estimation: IdData
    validation: IdData
    rows: tuple[ModelRow, ...]
    horizon: int | None = None
    ic: str = 'estimate'
    hints: tuple[str, ...] = field(default=())
    feedback: FeedbackTest | None = None
    kstep: int = KSTEP_HORIZON

    @property
    def closed_loop(self) -> bool:
        """True if the data were found to be taken in closed loop."""
        return self.feedback is not None and self.feedback.closed_loop

    @property
    def exit_status(self) -> int:
        """0 if every row is usable, 1 if some model is not (its row says why)."""
        return 0 if all(r.usable for r in self.rows) else 1


def check_channels(data: IdData) -> None:
    """Refuse data whose outputs cannot be identified from its inputs.

    Parameters
    ----------
    data : IdData
        The data set.

    Raises
    ------
    DegenerateDataError
        If an output is the same signal as an input (the same channel chosen
        twice, e.g. ``--rows 1 1``): the "model" would be ``y = u``, and
        the estimators' normal equations are singular; or if every input
        is constant (nothing excites the plant).
    """
    constant = constant_inputs(data)
    if constant and len(constant) == data.nu:
        shown = ', '.join(constant)
        raise DegenerateDataError(
            f'{"input" if len(constant) == 1 else "inputs"} {shown} '
            f'{"is" if len(constant) == 1 else "are"} constant: nothing excites the plant, '
            'so no model can be identified; record with a varying input (an excitation)'
        )
    for i, yname in enumerate(data.output_names):
        for j, uname in enumerate(data.input_names):
            if np.array_equal(data.y[:, i], data.u[:, j]):
                raise DegenerateDataError(
                    f'output {yname!r} and input {uname!r} are the same signal: '
                    'choose different channels (--rows OUTPUTS INPUTS)'
                )


def constant_inputs(data: IdData) -> list[str]:
    """Return the inputs that never change, as ``'name' (always value unit)`` texts.

    Parameters
    ----------
    data : IdData
        The data set (detrended or not).

    Returns
    -------
    list of str
        One text per constant input, empty if all vary.
    """
    return [
        f'{name!r} (always {data.u[0, j]:g}{" " + unit if unit else ""})'
        for j, (name, unit) in enumerate(zip(data.input_names, data.input_units, strict=True))
        if data.N and np.ptp(data.u[:, j]) == 0
    ]


def constant_hints(data: IdData) -> tuple[str, ...]:
    """Return a hint naming the constant inputs (models using them cannot be estimated).

    Parameters
    ----------
    data : IdData
        The data set.

    Returns
    -------
    tuple of str
        One line, or empty if every input varies.
    """
    constant = constant_inputs(data)
    if not constant:
        return ()
    return (
        f'{"input" if len(constant) == 1 else "inputs"} {", ".join(constant)} '
        f'{"is" if len(constant) == 1 else "are"} constant: it excites nothing, a model '
        'using it cannot be estimated (give it nb = 0 or leave the channel out)',
    )


def offset_hints(data: IdData) -> tuple[str, ...]:
    """Hints for channels with an offset large against their variation.

    Parameters
    ----------
    data : IdData
        Data as given to the estimators (not detrended).

    Returns
    -------
    tuple of str
        One line naming the channels whose ``|mean| > 0.5 std``, or empty.
    """
    channels = [
        (name, values)
        for names, block in ((data.output_names, data.y), (data.input_names, data.u))
        for name, values in zip(names, np.asarray(block).T, strict=True)
    ]
    offset = [
        name
        for name, v in channels
        if abs(float(np.mean(v))) > OFFSET_RATIO * max(float(np.std(v)), 1e-300)
    ]
    if not offset:
        return ()
    return (
        f'{", ".join(offset)} {"has an offset" if len(offset) == 1 else "have offsets"} '
        'large against the variation, and the models have no constant term: '
        'remove means with --detrend (MATLAB detrend(data)) unless the offset is '
        'part of the model',
    )


def _finite_fit(fit: np.ndarray) -> np.ndarray:
    fit = np.asarray(fit, dtype=float)
    return np.where(np.isfinite(fit), fit, np.nan)


def _nan(ny: int) -> np.ndarray:
    return np.full(ny, np.nan)


def _largest_pole(model: PolyModel) -> float:
    p = model.poles()
    return float(np.max(np.abs(p))) if len(p) else 0.0


def _fits(
    model: PolyModel, est: IdData, val: IdData, horizon: int | None, ic: str
) -> tuple[np.ndarray, np.ndarray]:
    """``compare`` fits on both parts; NaN where the simulation or predictor overflows."""
    out = []
    for d in (est, val):
        try:
            out.append(_finite_fit(compare(model, d, horizon, ic).fit))
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            out.append(_nan(model.ny))
    return out[0], out[1]


def _residual_reason(analysis: ResidualAnalysis, closed_loop: bool, structure: str) -> str:
    failed = analysis.failed_tests
    parts = []
    if 'whiteness' in failed:
        todo = 'raise the orders' + (
            ' or add a noise model (ARMAX, BJ)' if structure == 'arx' else ''
        )
        parts.append(
            f'the residuals are not white (statistic {analysis.whiteness_stat.max():.1f}, '
            f'limit {analysis.whiteness_limit:.1f}): dynamics or noise the model does not '
            f'describe; {todo}'
        )
    instruments = analysis.against == 'instruments'
    if 'independence' in failed:
        what = 'the instruments' if instruments else 'past inputs'
        parts.append(
            f'the residuals depend on {what} (statistic '
            f'{analysis.independence_stat.max(initial=0):.1f}, limit '
            f'{analysis.independence_limit:.1f}): input dynamics the model misses; raise '
            'the orders or check the delay nk'
        )
    if closed_loop and not instruments:
        parts.append('in closed loop such a model is also biased')
    return '; '.join(parts)


def _negligible(fit_val: np.ndarray, k_val: np.ndarray) -> bool:
    """Return True if every finite validation fit is at least :data:`NEGLIGIBLE_FIT` percent."""
    fits = np.r_[fit_val, k_val]
    fits = fits[np.isfinite(fits)]
    return bool(fits.size) and bool(np.all(fits >= NEGLIGIBLE_FIT))


def _fit_row(
    spec: ModelSpec,
    est: IdData,
    val: IdData,
    horizon: int | None,
    ic: str,
    max_iter: int | None,
    progress: Callable[[int, float], None] | None,
    label: str,
    instruments: np.ndarray | None = None,
    closed_loop: bool = False,
    kstep: int = KSTEP_HORIZON,
    val_instruments: np.ndarray | None = None,
    unexcited: tuple[str, ...] = (),
) -> ModelRow:
    ny = est.ny
    outputs = tuple(est.output_names)
    try:
        model = spec.fit(est, max_iter, progress, instruments)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as err:
        reason = f'estimation failed: {err}'
        if isinstance(err, np.linalg.LinAlgError) and 'singular' in str(err).lower():
            reason = (
                'estimation failed: singular equations, the data do not determine the '
                'parameters (an input that excites nothing, such as a constant one, or '
                'more parameters than the input excites): lower the orders or check the inputs'
            )
        return ModelRow(
            label, spec.structure, 'failed', reason, None, None,
            _nan(ny), _nan(ny), _nan(ny), None, (), outputs,
        )  # fmt: skip
    notes = []
    report = model.report
    if report is not None and not report.converged:
        notes.append(
            f'stopped at the iteration cap ({report.max_iter}) before converging: '
            'raise it with --max-iter'
        )
    pairs = cancelling_pairs(model)
    if pairs:
        shown = ', '.join(f'{root_text(p)}/{root_text(z)}' for p, z in pairs[:4])
        notes.append(
            f'{len(pairs)} pole-zero pair(s) nearly cancel (pole/zero {shown}'
            f'{", ..." if len(pairs) > 4 else ""}): orders above what the data support'
        )
    predicted = _nan(ny) if report is None else _finite_fit(report.fit)
    status, reason, validated = 'ok', '', model
    unstable = ''
    if not model.is_stable:
        reduced = without_cancelling_pairs(model)
        if reduced is not None and reduced.is_stable:
            status, validated = 'reduced', reduced
            reason = (
                f'unstable (largest pole {_largest_pole(model):.3g}); its unstable poles '
                f'cancel against zeros: validated without the {len(pairs)} cancelling '
                f'pair(s), as {" ".join(reduced.orders.describe().split())}'
            )
        else:
            status = 'unstable'
            unstable = f'unstable (largest pole {_largest_pole(model):.3g})'
            reason = (
                f'{unstable}: judged on {kstep}-step prediction, its simulation diverges '
                '(an open-loop-unstable plant, or orders above what the data support)'
            )
    fit_est, fit_val = _fits(validated, est, val, horizon, ic)
    if status == 'unstable' and horizon is None:  # a diverging simulation has no fit
        fit_est, fit_val = _nan(ny), _nan(ny)
    k_est, k_val = _fits(validated, est, val, kstep, ic)
    overflow = status != 'unstable' and not np.all(np.isfinite(np.r_[fit_est, fit_val]))
    try:
        external = spec.structure == 'iv' and val_instruments is not None
        analysis: ResidualAnalysis | None = resid(
            validated, val, closed_loop=closed_loop,
            instruments=val_instruments if external else None,
            noise_model=spec.structure not in ('oe', 'iv'),
        )  # fmt: skip
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as err:
        analysis, failure = None, str(err)
    if overflow or analysis is None or not np.all(np.isfinite(np.r_[k_est, k_val])):
        why = (
            'the simulation overflows' if overflow
            else failure if analysis is None
            else f'the {kstep}-step prediction overflows'
        )  # fmt: skip
        return ModelRow(
            label, spec.structure, 'diverges',
            f'{unstable + ": " if unstable else ""}validation failed: {why}; lower the orders',
            model, validated, fit_est, fit_val, predicted, analysis, tuple(notes), outputs,
            k_est, k_val, kstep,
        )  # fmt: skip
    biased = closed_loop and (
        spec.structure == 'oe' or (spec.structure == 'iv' and instruments is None)
    )
    if unexcited and not (spec.structure == 'iv' and instruments is not None):
        status = 'no excitation'
        reason = (
            f'{unstable + "; " if unstable else ""}closed loop without external excitation '
            f'({", ".join(unexcited)} is a linear function of the outputs): these data do not '
            'determine the plant, a model of the loop predicts as well as the plant; record '
            'with an excitation and use --iv with --instruments'
        )
    elif biased:
        status = 'closed-loop bias'
        method = 'output error' if spec.structure == 'oe' else 'IV with the input as instrument'
        reason = (
            f'{unstable + "; " if unstable else ""}{method} ignores the feedback in '
            'closed-loop data: the model describes the loop, not the plant; use --iv with '
            '--instruments (an excitation) or --armax/--bj judged on --horizon'
        )
    elif not analysis.passed and _negligible(fit_val, k_val):
        notes.append(
            f'the residual tests failed ({", ".join(analysis.failed_tests)}), but the model '
            f'explains {NEGLIGIBLE_FIT:g} % or more of the validation output: the residuals '
            'are at the resolution of (nearly) noise-free or quantised data, where any '
            'model error is significant; not counted against the model'
        )
    elif not analysis.passed:
        status = f'{" and ".join(analysis.failed_tests)} failed'
        prior = f'{reason.split(":")[0]}; ' if unstable else f'{reason}; ' if reason else ''
        reason = prior + _residual_reason(analysis, closed_loop, spec.structure)
    return ModelRow(
        label, spec.structure, status, reason, model, validated, fit_est, fit_val, predicted,
        analysis, tuple(notes), outputs, k_est, k_val, kstep,
    )  # fmt: skip


def identify(
    estimation: IdData,
    validation: IdData,
    specs: Sequence[ModelSpec],
    horizon: int | None = None,
    ic: str = 'estimate',
    max_iter: int | None = None,
    progress: Callable[[str, int, float], None] | None = None,
    hints: Sequence[str] = (),
    instruments: np.ndarray | None = None,
    validation_instruments: np.ndarray | None = None,
) -> Identification:
    """Fit and validate every requested model; one row each, none lost.

    Parameters
    ----------
    estimation, validation : IdData
        The two parts of the data (same channels).
    specs : sequence of ModelSpec
        Requested models.
    horizon : int or None
        Prediction horizon of the fits (None: simulation).
    ic : {'zero', 'estimate'}
        Initial conditions of the fits.
    max_iter : int, optional
        Iteration cap of the prediction-error methods.
    progress : callable, optional
        ``(label, step, loss)``: step 0 (loss NaN) when a model starts, then
        after every iteration of an iterative estimator.
    hints : sequence of str
        Advice about the data, passed through to the result.
    instruments : ndarray, shape (N, nz), optional
        External instruments for the IV models (the excitation of a closed
        loop), samples of ``estimation``.
    validation_instruments : ndarray, shape (N_val, nz), optional
        The same signals on the validation samples: IV models with external
        instruments are then tested for residual independence from them
        (in closed loop the inputs depend on the noise, the instruments do not).

    Returns
    -------
    Identification
        One :class:`ModelRow` per spec, in order.

    Raises
    ------
    DegenerateDataError
        If an output is the same signal as an input.
    ValueError
        If some spec's orders cannot be estimated on the data (checked for all
        specs before any model is fitted, so nothing computed is lost).
    """
    check_channels(estimation)
    for spec in specs:
        spec.check(estimation)
    hints = (*hints, *constant_hints(estimation))
    feedback = _feedback(estimation)
    closed = feedback is not None and feedback.closed_loop
    unexcited = () if feedback is None else feedback.unexcited
    kstep = KSTEP_HORIZON if horizon is None else int(horizon)
    rows = []
    for spec in specs:
        step = None
        if progress is not None:
            progress(spec.label, 0, float('nan'))
            step = _bind(progress, spec.label)
        with captured_fd_stdout() as lapack:
            row = _fit_row(
                spec, estimation, validation, horizon, ic, max_iter, step, spec.label,
                instruments, closed, kstep, validation_instruments, unexcited,
            )  # fmt: skip
        if lapack.text:
            row = _with_note(row, 'LAPACK: ' + ' '.join(lapack.text.split()))
        rows.append(row)
    return Identification(
        estimation, validation, tuple(rows), horizon, ic, tuple(hints), feedback, kstep
    )


def identify_outputs(
    estimation: IdData,
    validation: IdData,
    spec: ModelSpec,
    ic: str = 'estimate',
    hints: Sequence[str] = (),
) -> Identification:
    """One multi-input model per output (the lab's per-component models).

    An output that does not move relative to the others (standard deviation
    below 1e-9 of the largest, e.g. a field component that is zero by
    symmetry) gets a ``no response`` row instead of a model; if no output moves
    at all, every row is ``failed`` (nothing was excited).

    Parameters
    ----------
    estimation, validation : IdData
        The two parts of the data (detrended).
    spec : ModelSpec
        Structure and orders used for every output (scalar orders).
    ic : {'zero', 'estimate'}
        Initial conditions of the simulation fits.
    hints : sequence of str
        Advice about the data, passed through to the result.

    Returns
    -------
    Identification
        One row per output, in order; ``outputs`` names the row's output.
    """
    spread = np.std(np.asarray(estimation.y), axis=0)
    feedback = _feedback(estimation)
    closed = feedback is not None and feedback.closed_loop
    rows = []
    for i, name in enumerate(estimation.output_names):
        label = f'{spec.label} {name}'
        if spread[i] <= 1e-9 * spread.max():
            silent = not spread.max() > 0  # no output moves at all: nothing was excited
            rows.append(
                ModelRow(
                    label,
                    spec.structure,
                    'failed' if silent else 'no response',
                    'no output varies: the inputs did not reach the plant'
                    if silent
                    else 'constant after detrending (e.g. zero by symmetry)',
                    None,
                    None,
                    _nan(1),
                    _nan(1),
                    _nan(1),
                    None,
                    (),
                    (name,),
                )  # fmt: skip
            )
            continue
        est, val = estimation.select(outputs=[i]), validation.select(outputs=[i])
        with captured_fd_stdout() as lapack:
            row = _fit_row(
                spec, est, val, None, ic, None, None, label, None, closed,
                unexcited=() if feedback is None else feedback.unexcited,
            )  # fmt: skip
        if lapack.text:
            row = _with_note(row, 'LAPACK: ' + ' '.join(lapack.text.split()))
        rows.append(row)
    return Identification(estimation, validation, tuple(rows), None, ic, tuple(hints), feedback)


def _feedback(data: IdData) -> FeedbackTest | None:
    """Return the closed-loop test of ``data``; None if it cannot run (no inputs, too short)."""
    varying = [j for j in range(data.nu) if np.ptp(data.u[:, j]) > 0]
    if not varying or np.all(np.ptp(data.y, axis=0) == 0):
        return None
    try:
        with captured_fd_stdout():
            return detect_feedback(data.select(inputs=varying))
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


def _bind(progress: Callable[[str, int, float], None], label: str) -> Callable[[int, float], None]:
    return lambda step, loss: progress(label, step, loss)


def _with_note(row: ModelRow, note: str) -> ModelRow:
    return replace(row, notes=(*row.notes, note))
