"""``maglev-sysid`` beyond the linear fits: NARX, confidence bands, reduction, several files.

Options added to the parser by :func:`add_arguments`:

- ``--narx NA NB NK DEGREE`` (repeatable): polynomial NARX by FROLS
  (:mod:`maglev_ros.sysid.narx`), ``--criterion`` and ``--max-terms``;
- ``--confidence [SIGMA]``: with ``--plot``, Bode, step and simulated-output
  plots with SIGMA-standard-deviation bands (default 3); the parameter
  covariance is in ``--json`` in any case;
- ``--reduce [ORDER]``: balanced truncation of every linear model to ORDER
  states, or by ``--reduce-fraction`` of the Hankel singular values;
- several data files (or bags): estimated as one data set (no samples joined
  across files) and validated by ``--kfold [K]`` (default: leave one file out)
  or ``--by-experiment``;
- ``--sindy``: SINDy with control on the states recorded in bags, with the
  physics check of its linearisation.
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path
from typing import Any

import numpy as np

from ..topics import ESTIMATE_TOPIC, TRUE_STATE_TOPIC
from .usage import UsageError

__all__ = [
    'add_arguments',
    'check_arguments',
    'extend_single',
    'filtered',
    'run_several',
    'run_sindy',
]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the NARX, confidence, reduction and several-file options to ``p``.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The ``maglev-sysid`` parser; the options go into a new argument group.
    """
    g = p.add_argument_group('nonlinear models, confidence, reduction, several data files')
    g.add_argument(
        '--narx',
        nargs=4,
        type=int,
        action='append',
        metavar=('NA', 'NB', 'NK', 'DEGREE'),
        help='polynomial NARX: output lags 1..NA, input lags NK..NK+NB-1, monomials up to '
        'DEGREE, terms chosen by FROLS (one selection per output)',
    )
    g.add_argument(
        '--criterion',
        choices=('bic', 'aic', 'fpe'),
        default='bic',
        help='information criterion for the number of NARX terms (default bic)',
    )
    g.add_argument('--max-terms', type=int, default=30, help='most NARX terms per output')
    g.add_argument(
        '--confidence',
        type=float,
        nargs='?',
        const=3.0,
        metavar='SIGMA',
        help='with --plot: Bode, step and simulated output with SIGMA-standard-deviation '
        'confidence bands (default 3, as the toolbox)',
    )
    g.add_argument(
        '--reduce',
        nargs='?',
        const='auto',
        metavar='ORDER',
        help='balanced truncation of each linear model to ORDER states, or (no value) to '
        'the fewest keeping --reduce-fraction of the Hankel singular values',
    )
    g.add_argument(
        '--reduce-fraction',
        type=float,
        default=0.99,
        help='share of the Hankel singular values kept by --reduce (default 0.99)',
    )
    g.add_argument(
        '--kfold',
        type=int,
        nargs='?',
        const=0,
        metavar='K',
        help='several data files: K-fold cross-validation over the files '
        '(default, and without K: leave one file out)',
    )
    g.add_argument(
        '--sindy',
        action='store_true',
        help='SINDy with control (pysindy) on the bag(s): the 12-state of --state-topic and '
        'the coil currents, 10 states around the equilibrium of --params; prints the '
        'equations and checks their linearisation against the physics',
    )
    g.add_argument(
        '--state-topic',
        default=TRUE_STATE_TOPIC,
        help=f'--sindy: Odometry topic of the states (default {TRUE_STATE_TOPIC}; '
        f'{ESTIMATE_TOPIC} for an estimator)',
    )
    g.add_argument('--sindy-degree', type=int, default=2, help='--sindy: library degree')
    g.add_argument(
        '--sindy-threshold',
        type=float,
        default=0.5,
        help='--sindy: STLSQ threshold in mm, mrad, mm/s, mrad/s units (default 0.5)',
    )
    g.add_argument(
        '--params',
        default='maggy_v2',
        help='--sindy: parameter set of the physics check (default maggy_v2)',
    )
    g.add_argument(
        '--by-experiment',
        action='store_true',
        help='several data files: estimate on each file alone, validate on the others',
    )


def check_arguments(args: argparse.Namespace) -> None:
    """Refuse bad values of the added options (UsageError, one line).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments, with the options of :func:`add_arguments` and ``args.data``
        the list of data files.
    """
    for na, nb, nk, degree in args.narx or []:
        if na < 1 or nb < 0 or nk < 0 or not 1 <= degree <= 4:
            raise UsageError(
                f'--narx {na} {nb} {nk} {degree}: need NA >= 1, NB >= 0, NK >= 0 and '
                'DEGREE from 1 to 4'
            )
    if args.max_terms < 1:
        raise UsageError(f'--max-terms must be >= 1, got {args.max_terms}')
    if args.confidence is not None and not args.confidence > 0:
        raise UsageError(f'--confidence must be a positive number of std, got {args.confidence}')
    if args.reduce not in (None, 'auto'):
        try:
            order = int(args.reduce)
        except ValueError:
            order = -1
        if order < 0:
            raise UsageError(f'--reduce takes a state count such as 4, got {args.reduce!r}')
    if not 0.0 < args.reduce_fraction <= 1.0:
        raise UsageError(f'--reduce-fraction must be in (0, 1], got {args.reduce_fraction}')
    if args.sindy and not 1 <= args.sindy_degree <= 3:
        raise UsageError(f'--sindy-degree must be 1, 2 or 3, got {args.sindy_degree}')
    if args.sindy and not args.sindy_threshold >= 0:
        raise UsageError(f'--sindy-threshold must be >= 0, got {args.sindy_threshold}')
    several = len(args.data) > 1
    if not several and (args.kfold is not None or args.by_experiment):
        raise UsageError('--kfold and --by-experiment need several data files')
    if several and (args.reduce is not None or args.confidence is not None):
        raise UsageError(
            '--reduce and --confidence take one data file (the covariance is in --json)'
        )
    if several and args.kfold is not None and args.by_experiment:
        raise UsageError('choose --kfold or --by-experiment, not both')
    if several and args.kfold and not 2 <= args.kfold <= len(args.data):
        raise UsageError(
            f'--kfold K must be from 2 to {len(args.data)} (the files), got {args.kfold}'
        )


# ------------------------------------------------------------------ NARX rows
def _narx_entry(model: Any, est: Any, val: Any, horizon: int | None, ic: str) -> dict[str, Any]:
    from maglev_ros.sysid import compare, resid

    fit_est = compare(model, est, horizon, ic).fit
    fit_val = compare(model, val, horizon, ic).fit
    analysis = resid(model, val, skip=model.structure.max_lag)
    finite = bool(np.all(np.isfinite(model.simulate(val))))
    return {
        'model': model,
        'analysis': analysis,
        'label': _narx_label(model),
        'structure': 'narx',
        'status': 'ok' if finite else 'unstable',
        'reason': '' if finite else 'the simulation diverges on the validation data',
        'fit_estimation': fit_est,
        'fit_validation': fit_val,
        'terms': [
            {
                'output': model.output_names[i],
                'names': model.term_names(i),
                'theta': model.theta[i],
                'std': model.std[i],
                'covariance': model.covariance[i],
            }
            for i in range(model.ny)
        ],
        'residuals_white': analysis.white,
        'residuals_independent': analysis.independent,
    }


def _narx_label(model: Any) -> str:
    s = model.structure
    return f'NARX {s.na} {s.nb} {s.nk} {s.degree}'


def _fit_narx(args: argparse.Namespace, data: Any, spec: list[int]) -> Any:
    from maglev_ros.sysid.narx import narx

    na, nb, nk, degree = spec
    return narx(data, na, nb, nk, degree, criterion=args.criterion, max_terms=args.max_terms)


def _percent(values: np.ndarray) -> str:
    return ', '.join('n/a' if not np.isfinite(f) else f'{f:.2f}%' for f in values)


def extend_single(
    args: argparse.Namespace, est: Any, val: Any, result: Any, summary: dict[str, Any]
) -> tuple[list[str], list[Path], int]:
    """NARX rows, confidence plots and reductions for one data file.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (``--narx``, ``--confidence``, ``--reduce``, ``--plot``,
        ``--horizon``, ``--ic``, ...).
    est : IdData
        Estimation data the NARX models are fitted on.
    val : IdData
        Validation data of the fits, residual tests, bands and reductions.
    result : Identification
        The linear identification of the same data (its ``rows`` give the
        models whose confidence bands and reductions are made).
    summary : dict
        The JSON summary; NARX rows are appended to ``summary['models']`` and
        reductions added to the linear models' entries, in place.

    Returns
    -------
    tuple of (list of str, list of Path, int)
        The text blocks to print, the PNGs written and the exit status of the
        added rows (0 all usable, 1 some failed or unstable).
    """
    from maglev_ros import sysid

    texts: list[str] = []
    written: list[Path] = []
    status = 0
    plot_dir = Path(args.plot) if args.plot else None
    what = 'simulation' if args.horizon is None else f'{args.horizon}-step prediction'
    narx_rows = []
    for spec in args.narx or []:
        label = 'NARX ' + ' '.join(str(v) for v in spec)
        try:
            row = _narx_entry(_fit_narx(args, est, spec), est, val, args.horizon, args.ic)
        except ValueError as exc:
            status = 1
            summary['models'].append({'label': label, 'structure': 'narx', 'status': 'failed',
                                      'reason': str(exc)})  # fmt: skip
            texts.append(f'{label}: failed: {exc}')
            continue
        narx_rows.append(row)
        status = max(status, 0 if row['status'] == 'ok' else 1)
        entry = {k: v for k, v in row.items() if k not in ('model', 'analysis')}
        summary['models'].append(entry)
        texts.append(
            f'{row["model"]}\n  Compare ({what}, ic={args.ic}): fit to estimation data '
            f'{_percent(row["fit_estimation"])}; validation data {_percent(row["fit_validation"])}'
            f'\n  Validation {row["analysis"].summary()}'
            + (f'\n  Unstable: {row["reason"]}' if row['reason'] else '')
        )
    if plot_dir and narx_rows:
        plot_dir.mkdir(parents=True, exist_ok=True)
        written.append(
            sysid.compare_plot(
                val,
                [r['model'] for r in narx_rows],
                plot_dir / 'compare_narx.png',
                [r['label'] for r in narx_rows],
                args.horizon,
                args.ic,
            )  # fmt: skip
        )
        for k, r in enumerate(narx_rows, start=1):
            written.append(
                sysid.resid_plot(
                    r['analysis'],
                    plot_dir / f'resid_narx_{k}.png',
                    val.output_names,
                    val.input_names,
                    model_label=r['label'],
                )  # fmt: skip
            )
    linear = [(k, r) for k, r in enumerate(result.rows, start=1) if r.model is not None]
    if args.confidence is not None and plot_dir and linear:
        written += _confidence_plots(args.confidence, linear, val, plot_dir)
    if args.reduce is not None:
        texts += _reductions(args, linear, val, summary, plot_dir, written)
    return texts, written, status


def _confidence_plots(sigma: float, linear: list, val: Any, plot_dir: Path) -> list[Path]:
    from maglev_ros.sysid.confidence_plots import (
        bode_band_plot,
        output_band_figure,
        step_band_figure,
    )
    from maglev_ros.sysid.plots import _save

    models = [r.model for _, r in linear if r.model.covariance is not None]
    labels = [r.label for _, r in linear if r.model.covariance is not None]
    if not models:
        return []
    out = [bode_band_plot(models, plot_dir / 'bode_confidence.png', labels, sigma)]
    steps = max(50, min(2000, int(round(0.2 / models[0].Ts))))
    out.append(
        _save(step_band_figure(models, steps, labels, sigma), plot_dir / 'step_confidence.png')
    )
    for (k, row), model in zip(((k, r) for k, r in linear if r.model.covariance is not None),
                               models, strict=True):  # fmt: skip
        out.append(
            _save(
                output_band_figure(model, val, row.label, sigma),
                plot_dir / f'output_confidence_{k}_{row.structure}.png',
            )
        )
    return out


def _reductions(
    args: argparse.Namespace,
    linear: list,
    val: Any,
    summary: dict[str, Any],
    plot_dir: Path | None,
    written: list[Path],
) -> list[str]:
    from maglev_ros.sysid.reduction import balanced_truncation
    from maglev_ros.sysid.reduction_plots import reduction_plot

    texts = []
    order = None if args.reduce == 'auto' else int(args.reduce)
    for k, row in linear:
        try:
            red = balanced_truncation(row.model, order=order, fraction=args.reduce_fraction)
            full_fit, reduced_fit = red.fit_loss(val, args.ic)
        except (ValueError, np.linalg.LinAlgError) as exc:
            texts.append(f'{row.label}: reduction failed: {exc}')
            summary['models'][k - 1]['reduction'] = {'error': str(exc)}
            continue
        texts.append(
            f'{row.label}: {red.summary()}\n  validation simulation fit: full '
            f'{_percent(full_fit)}, reduced {_percent(reduced_fit)}'
        )
        summary['models'][k - 1]['reduction'] = {
            'order': red.order,
            'full_order': red.full.order,
            'unstable_states': red.n_unstable,
            'hankel_singular_values': red.hsv,
            'fraction_kept': red.fraction,
            'error_bound': red.error_bound,
            'fit_full': full_fit,
            'fit_reduced': reduced_fit,
        }
        if plot_dir:
            written.append(reduction_plot(red, plot_dir / f'reduction_{k}_{row.structure}.png'))
    return texts


# ---------------------------------------------------------- several data files
def filtered(args: argparse.Namespace, data: Any) -> Any:
    """Apply ``--filter LOW HIGH`` to ``data``, refusing a band above its Nyquist frequency.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (``filter``, ``filter_order``, ``zero_phase``).
    data : IdData
        The data set, sampled at ``data.Ts`` seconds.

    Returns
    -------
    IdData
        The filtered data (``data`` itself without ``--filter``).

    Raises
    ------
    UsageError
        LOW at or above Nyquist, or a finite HIGH above it (``inf`` asks for a
        high-pass filter).
    """
    if not args.filter:
        return data
    low, high = args.filter
    nyquist = 0.5 / data.Ts
    if low >= nyquist or (high > nyquist and high != float('inf')):
        raise UsageError(
            f'--filter {low:g} {high:g}: the band is above the Nyquist frequency '
            f'{nyquist:g} Hz of the data (Ts {data.Ts:g} s): give edges up to {nyquist:g} Hz '
            '(HIGH inf: high-pass)'
        )
    return data.filter((low, high), args.filter_order, args.zero_phase)


def _prepare(args: argparse.Namespace, data: Any) -> Any:
    if args.detrend:
        data = data.detrend(args.detrend)
    data = filtered(args, data)
    if args.decimate != 1:
        data = data.decimate(args.decimate)
    return data


def run_several(args: argparse.Namespace, load: Any, plain: Any, requested: list) -> int:
    """Identify on several data files as one data set and cross-validate over them.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (``args.data`` a list of paths).
    load : callable
        ``load(args, notes) -> (IdData, n_instruments)`` for one file (``args.data`` a
        path); what ``--allow-gaps`` left out goes into ``notes``.
    plain : callable
        JSON-safe conversion.
    requested : list of ModelSpec
        The linear models asked for.

    Returns
    -------
    int
        Exit status: 0 every model and fold usable, 1 otherwise.
    """
    import json

    from maglev_ros import sysid
    from maglev_ros.sysid.experiments import by_experiment, kfold

    if args.instruments:
        raise UsageError('--instruments takes one data file; give the files one at a time')
    if args.select:
        raise UsageError('--select takes one data file; choose orders with --arx on several')
    experiments = []
    notes: list[str] = []
    for path in args.data:
        one = copy.copy(args)
        one.data = path
        data, _ = load(one, notes)
        experiments.append(_prepare(args, data))
    labels = _labels(args.data)
    try:
        experiments = list(sysid.merge(*experiments))
    except ValueError as exc:
        raise UsageError(f'the data files do not fit together: {exc}') from None
    first = experiments[0]
    estimators: list[tuple[str, Any]] = []
    for spec in requested:
        try:
            spec.check(first)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        estimators.append((spec.label, lambda d, s=spec: s.fit(tuple(d), args.max_iter)))
    for narx_spec in args.narx or []:
        estimators.append(
            ('NARX ' + ' '.join(map(str, narx_spec)), lambda d, s=narx_spec: _fit_narx(args, d, s))
        )
    if not estimators:
        raise UsageError(
            'no model requested: give --arx, --iv, --armax, --oe, --bj, --spec or --narx'
        )
    summary: dict[str, Any] = {
        'data': {
            'files': list(args.data),
            'N': [d.N for d in experiments],
            'ny': first.ny,
            'nu': first.nu,
            'Ts': first.Ts,
            'outputs': list(first.output_names),
            'inputs': list(first.input_names),
        },
        'models': [],
    }
    status = 0
    blocks = []
    for label, estimate in estimators:
        entry: dict[str, Any] = {'label': label}
        try:
            model = estimate(experiments)
        except ValueError as exc:
            entry.update(status='failed', reason=str(exc))
            summary['models'].append(entry)
            blocks.append(f'{label}: failed on all files together: {exc}')
            status = 1
            continue
        if args.by_experiment:
            table = by_experiment(experiments, estimate, labels, args.horizon, args.ic)
        else:
            table = kfold(experiments, estimate, args.kfold or None, labels, args.horizon, args.ic)
        if any(f.error for f in table.folds) or not np.all(np.isfinite(table.fits)):
            status = 1
        if hasattr(model, 'orders'):
            entry.update(sysid.model_to_dict(model))
            entry['std'] = model.std
        else:
            entry['terms'] = [
                {'output': model.output_names[i], 'names': model.term_names(i),
                 'theta': model.theta[i], 'std': model.std[i],
                 'covariance': model.covariance[i]}
                for i in range(model.ny)
            ]  # fmt: skip
        entry['folds'] = table.to_dict()
        summary['models'].append(entry)
        kind = 'by experiment' if args.by_experiment else 'k-fold over the files'
        blocks.append(f'{model}\n  Validation {kind}:\n' + _indent(table.text(), 4))
    summary['exit_status'] = status
    summary['notes'] = notes
    if args.json:
        print(json.dumps(plain(summary), indent=1))
        return status
    sizes = ', '.join(f'{name} ({d.N})' for name, d in zip(labels, experiments, strict=True))
    print(
        f'maglev-sysid: {len(experiments)} experiments as one data set, {first.ny} output(s), '
        f'{first.nu} input(s), Ts = {first.Ts:g} s: {sizes}'
    )
    for note in notes:
        print(f'note: {note}')
    for block in blocks:
        print('\n' + block)
    return status


def _labels(paths: list[str]) -> list[str]:
    """Shortest distinct path tails: ``run1.npz``, or ``lab1/bag`` for bags all named ``bag``."""
    parts = [Path(p).resolve().parts for p in paths]
    for depth in range(1, max(len(p) for p in parts) + 1):
        labels = ['/'.join(p[-depth:]) for p in parts]
        if len(set(labels)) == len(labels):
            return labels
    return [str(p) for p in paths]


def _indent(text: str, n: int) -> str:
    return '\n'.join(' ' * n + line for line in text.splitlines())


# ---------------------------------------------------------------------- SINDy
SINDY_TOLERANCE = 0.10  # relative eigenvalue error accepted by the physics check


def run_sindy(args: argparse.Namespace, plain: Any) -> int:
    """SINDy on the states of one or several bags, with the physics check.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (``args.data`` the bag directories, ``--state-topic``,
        ``--params``, ``--sindy-degree``, ``--sindy-threshold``, ``--json``).
    plain : callable
        JSON-safe conversion (arrays to lists, NaN/inf to None) for ``--json``.

    Returns
    -------
    int
        0 when the unstable and oscillatory eigenvalues are within 10 % of the
        physics linearisation's, 1 otherwise (everything is still printed).
    """
    import json
    import warnings

    from maglev_ros.bags import BagError, is_bag_path
    from maglev_ros.physics import linearize, make_model
    from maglev_ros.sysid.sindy import eigenvalue_check, sindy_magnet
    from maglev_ros.sysid.state_trajectories import bag_states

    for path in args.data:
        if not is_bag_path(path):
            raise UsageError(f'--sindy reads states from bags; {path} is not a bag directory')
    try:
        linear = linearize(make_model(args.params))
    except (ValueError, OSError) as exc:
        raise UsageError(f'--params {args.params}: {exc}') from None
    trajectories = []
    for path in args.data:
        try:
            trajectories.append(bag_states(path, args.state_topic))
        except BagError as exc:
            raise UsageError(f'{path}: {exc}') from None
    dts = {round(t.dt, 12) for t in trajectories}
    if len(dts) > 1:
        raise UsageError(f'the bags have different sample times {sorted(dts)} s')
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # pysindy's sparsity warnings: the check says it
        model = sindy_magnet(
            [t.x for t in trajectories], [t.u for t in trajectories], trajectories[0].dt,
            linear, args.sindy_degree, args.sindy_threshold,
        )  # fmt: skip
    checks = eigenvalue_check(model, linear)
    passed = all(c.error < SINDY_TOLERANCE for c in checks)
    status = 0 if passed else 1
    if args.json:
        print(json.dumps(plain({
            'bags': list(args.data),
            'state_topic': args.state_topic,
            'samples': [len(t.x) for t in trajectories],
            'states': list(model.state_names),
            'inputs': list(model.input_names),
            'units': 'mm, mrad, mm/s, mrad/s, A; around the equilibrium of ' + args.params,
            'features': model.feature_names,
            'coefficients': model.coefficients,
            'equations': model.equations(),
            'eigenvalue_check': [
                {'mode': c.name, 'physics': [c.physics.real, c.physics.imag],
                 'sindy': [c.found.real, c.found.imag], 'relative_error': c.error}
                for c in checks
            ],
            'exit_status': status,
        }), indent=1))  # fmt: skip
        return status
    samples = ', '.join(str(len(t.x)) for t in trajectories)
    print(
        f'maglev-sysid --sindy: {args.state_topic} of {len(trajectories)} bag(s) ({samples} '
        f'samples, Ts = {trajectories[0].dt:g} s); states in mm, mrad, mm/s, mrad/s around '
        f'the equilibrium of {args.params}, coil currents in A'
    )
    print(str(model).splitlines()[0])
    for line in model.equations(2):
        print('  ' + line)
    print(f'Linearised at the equilibrium, against the physics ({args.params}):')
    for c in checks:
        print(
            f'  {c.name:<20} physics {c.physics.real:+8.2f} {c.physics.imag:+8.2f}j  SINDy '
            f'{c.found.real:+8.2f} {c.found.imag:+8.2f}j 1/s  ({100 * c.error:.2f} %)'
        )
    verdict = 'ok' if passed else 'FAILED'
    print(f'physics check {verdict}: every mode within {100 * SINDY_TOLERANCE:.0f} %')
    return status
