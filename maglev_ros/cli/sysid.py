"""``maglev-sysid``: identify polynomial models from input/output data files.

The lab's MATLAB workflow (``iddata``, ``detrend``, ``idfilt``, ``arx``, ``iv4``,
``armax``, ``oe``, ``bj``, ``compare``, ``resid``) on the command line::

    maglev-sysid data.mat --rows 1 4 --ts 2e-4 --detrend --arx 7 9 1 --iv 7 9 1
    maglev-sysid data.mat --rows 1 4 --ts 2e-4 --armax 5 5 3 1 --plot plots/

Every requested model gets its own result (:mod:`maglev_ros.sysid.workflow`):
a model that fails or is unstable is reported with the reason and NaN fits,
and the others, the plots and the saved models are unaffected.

Exit status: 0 when every model is usable (``ok``, ``reduced``, ``unstable``
with passing residuals, ``no response``), 1 when some model is not (a failed
residual test, closed-loop bias, no excitation, a diverging predictor, a
failed estimator: its row says why; all results are still printed and
written), 2 on bad input (one line on stderr).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..topics import EXCITATION_TOPIC
from .usage import Parser, UsageError, check_output_dir, limit_blas_threads, run_command

__all__ = ['build_parser', 'main', 'run']

PROG = 'maglev-sysid'
EPILOG = (
    'Without --detrend the models fit the raw values, offsets included (the '
    'polynomial models have no constant term); --detrend removes the means first, '
    "as MATLAB's detrend(data). Closed-loop data are detected and said so, with "
    'what to do. Every model gets a simulation and a k-step prediction fit (5 '
    'samples, or --horizon) and a residual verdict. Exit status: 0 every model '
    'usable (ok, reduced, unstable with passing residuals), 1 some model not usable: '
    'a residual test failed, closed-loop bias, no excitation, diverging, failed '
    '(its row says why; all results are still printed and '
    'written), 2 bad input.'
)


def _int_list(text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(',') if v.strip()]
    except ValueError:
        message = f'expected comma-separated integers, got {text!r}'
        raise argparse.ArgumentTypeError(message) from None


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-sysid``."""
    p = Parser(
        prog=PROG,
        description='Identify ARX/IV/ARMAX/OE/BJ models from data '
        'files, like the MATLAB System Identification Toolbox.',
        epilog=EPILOG,
    )
    p.add_argument(
        'data',
        nargs='+',
        help='data file (.npz, .csv or MATLAB .mat, v7 or older) or a '
        'rosbag2 bag directory (then choose channels with --output/--input); '
        'several: one data set of several experiments (see --kfold)',
    )
    from .bag2data import add_channel_arguments

    add_channel_arguments(p)
    p.add_argument('--ts', type=float, help='sample time in seconds (default: from file)')
    p.add_argument(
        '--rows',
        nargs=2,
        type=_int_list,
        metavar=('OUTPUTS', 'INPUTS'),
        help='rows of the channel matrix (e.g. DATA) used as outputs and inputs, '
        'counted from 1, comma-separated (e.g. --rows 1,2 4,5)',
    )
    p.add_argument('--matrix', default='DATA', help='name of the channel matrix (default DATA)')
    p.add_argument('--outputs', help='CSV output column names, comma-separated')
    p.add_argument('--inputs', help='CSV input column names, comma-separated')
    p.add_argument(
        '--split',
        default='0.5',
        help='estimation/validation split: fraction (0.5) or sample count (12500)',
    )
    p.add_argument(
        '--detrend',
        nargs='?',
        const='constant',
        choices=('constant', 'linear'),
        help='remove offsets before estimation (off unless given): --detrend removes '
        'the means, --detrend linear a straight line per channel',
    )
    p.add_argument(
        '--filter',
        nargs=2,
        type=float,
        metavar=('LOW', 'HIGH'),
        help='Butterworth pass band in Hz, up to Nyquist (LOW 0: low-pass, HIGH inf: '
        'high-pass), like idfilt',
    )
    p.add_argument('--filter-order', type=int, default=5, help='filter order (default 5)')
    p.add_argument('--zero-phase', action='store_true', help='filter forwards and backwards')
    p.add_argument('--decimate', type=int, default=1, help='decimation factor (default 1)')
    p.add_argument('--arx', nargs=3, type=int, action='append', metavar=('NA', 'NB', 'NK'))
    p.add_argument(
        '--iv',
        nargs=3,
        type=int,
        action='append',
        metavar=('NA', 'NB', 'NK'),
        help='four-stage instrumental variables (iv4)',
    )
    p.add_argument(
        '--instruments',
        action='append',
        default=[],
        metavar='CHANNEL',
        help='closed-loop data: external signal (the excitation) used as the '
        'instruments of --iv, repeat for more. A bag: a channel spec like '
        f"--input ('r={EXCITATION_TOPIC}:data[0]'); a channel matrix "
        'with --rows: its row (counted from 1); CSV: a column name; npz/mat: a '
        'variable of shape (N,) or (N, k)',
    )
    p.add_argument('--armax', nargs=4, type=int, action='append', metavar=('NA', 'NB', 'NC', 'NK'))
    p.add_argument('--oe', nargs=3, type=int, action='append', metavar=('NB', 'NF', 'NK'))
    p.add_argument(
        '--bj', nargs=5, type=int, action='append', metavar=('NB', 'NC', 'ND', 'NF', 'NK')
    )
    p.add_argument(
        '--spec',
        help='YAML file with a "models" list (structure and order '
        'matrices na, nb, nc, nk ... for MIMO models)',
    )
    p.add_argument(
        '--select',
        nargs='?',
        const='val',
        choices=('val', 'aic', 'mdl'),
        help='ARX order search (SISO) by validation loss, AIC or MDL',
    )
    p.add_argument(
        '--select-max',
        nargs=3,
        type=int,
        default=[10, 10, 1],
        metavar=('NA', 'NB', 'NK'),
        help='search na, nb in 1..max, nk in 1..max',
    )
    p.add_argument('--horizon', type=int, help='compare k-step predictions instead of simulation')
    p.add_argument(
        '--ic',
        choices=('zero', 'estimate'),
        default='estimate',
        help='initial conditions for compare (default estimate, as the toolbox)',
    )
    p.add_argument(
        '--max-iter',
        type=int,
        default=None,
        help='iteration cap of ARMAX/OE/BJ (default 50 for ARMAX, 100 for OE/BJ); '
        'reaching it is reported',
    )
    p.add_argument('--json', action='store_true', help='print a JSON result instead of text')
    p.add_argument('--quiet', action='store_true', help='no progress display')
    p.add_argument('--plot', metavar='DIR', help='write compare/resid/bode PNGs into DIR')
    p.add_argument('--save', metavar='DIR', help='save each model as JSON into DIR')
    from .sysid_extra import add_arguments

    add_arguments(p)
    return p


def _spec_models(path: str) -> list[Any]:
    import yaml

    from maglev_ros.sysid.workflow import ModelSpec
    from maglev_ros.yaml_errors import yaml_error_text

    spec_path = Path(path)
    if not spec_path.is_file():
        raise UsageError(f'spec file {path!r} does not exist')
    try:
        spec = yaml.safe_load(spec_path.read_text())
    except yaml.YAMLError as exc:
        raise UsageError(f'spec file {path!r} is not valid YAML: {yaml_error_text(exc)}') from None
    models = spec.get('models') if isinstance(spec, dict) else None
    if not isinstance(models, list) or not models:
        raise UsageError(f'spec file {path!r} needs a non-empty "models" list')
    out = []
    for k, entry in enumerate(models):
        if not isinstance(entry, dict) or 'structure' not in entry:
            raise UsageError(f'spec model {k + 1} needs a "structure" field')
        structure = str(entry['structure']).lower().replace('iv4', 'iv')
        orders = {key: v for key, v in entry.items() if key != 'structure'}
        try:
            out.append(ModelSpec(structure, orders))
        except ValueError as err:
            raise UsageError(f'spec model {k + 1}: {err}') from None
    return out


# orders of which at least one must be > 0 for a model to have a parameter to estimate
# (OE and BJ without B are no input model: their F is then undetermined)
_ESTIMATED = {
    'arx': ('na', 'nb'),
    'iv': ('na', 'nb'),
    'armax': ('na', 'nb', 'nc'),
    'oe': ('nb',),
    'bj': ('nb',),
}


def _check_something_to_estimate(structure: str, orders: dict[str, int]) -> None:
    """Refuse orders that leave a model with no parameter to estimate (UsageError)."""
    names = _ESTIMATED[structure]
    if all(orders[name] == 0 for name in names):
        given = ' '.join(str(v) for v in orders.values())
        zero = ' and '.join(name for name in names)
        raise UsageError(
            f'--{structure} {given}: {zero} {"are" if len(names) > 1 else "is"} 0, so the '
            f'model has nothing to estimate: give {" or ".join(n.upper() for n in names)} >= 1'
        )


def _requested(args: argparse.Namespace) -> list[Any]:
    from maglev_ros.sysid.workflow import ORDER_NAMES, ModelSpec

    out = []
    for structure, keys in ORDER_NAMES.items():
        for values in getattr(args, structure) or []:
            orders = dict(zip(keys, values, strict=True))
            _check_something_to_estimate(structure, orders)
            out.append(ModelSpec(structure, orders))
    if args.spec:
        out += _spec_models(args.spec)
    return out


def _plain(value: Any) -> Any:
    """JSON-safe copy: arrays to lists, NaN/inf to None."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


FIT_FLOOR = -999.0  # fits below are shown as "< -999" (a diverging prediction)


def _fit_text(value: float, suffix: str = '') -> str:
    if not np.isfinite(value):
        return 'n/a'
    if value < FIT_FLOOR:
        return f'<{FIT_FLOOR:.0f}{suffix}'
    return f'{value:.2f}{suffix}'


def _percent(values: np.ndarray) -> str:
    return ', '.join(_fit_text(f, '%') for f in values)


def _row_text(row: Any, what: str, ic: str) -> str:
    lines = [] if row.model is None else [str(row.model)]
    if row.status in ('failed', 'no response'):
        lines.append(f'{row.label}: {row.reason}')
    else:
        lines.append(
            f'  Compare ({what}, ic={ic}): fit to estimation data '
            f'{_percent(row.fit_estimation)}; validation data {_percent(row.fit_validation)}'
        )
        lines.append(
            f'  Compare ({row.kstep}-step prediction, ic={ic}): fit to estimation data '
            f'{_percent(row.kstep_estimation)}; validation data {_percent(row.kstep_validation)}'
        )
        if row.residuals is not None:
            lines.append(f'  Validation {row.residuals.summary()}')
        if row.status != 'ok':
            lines.append(f'  {row.status.capitalize()}: {row.reason}')
    lines += [f'  Note: {note}' for note in row.notes]
    return '\n'.join(lines)


def _summary_table(result: Any, what: str) -> str:
    rows = result.rows
    width = max(len('model'), *(len(r.label) for r in rows))
    kstep = f'{result.kstep}-step val. %'
    resid_width = max(len('residuals'), *(len(r.residual_verdict) for r in rows))
    lines = [
        f'Summary ({what} and {result.kstep}-step prediction, ic={result.ic}; fits per output):',
        f'  {"model":<{width}}  {"fit est. %":>12}  {"fit val. %":>12}  {kstep:>16}  '
        f'{"residuals":<{resid_width}}  status',
    ]
    for r in rows:
        est = ' '.join(_fit_text(f) for f in r.fit_estimation)
        val = ' '.join(_fit_text(f) for f in r.fit_validation)
        ahead = ' '.join(_fit_text(f) for f in r.kstep_validation)
        status = r.status
        if r.status == 'reduced':
            status += f' (validated as {" ".join(r.validated.orders.describe().split())})'
        elif r.status == 'unstable':
            status += ' (simulation diverges: judged on k-step prediction)'
        if not r.usable:
            status += ' - not usable'
        lines.append(
            f'  {r.label:<{width}}  {est:>12}  {val:>12}  {ahead:>16}  '
            f'{r.residual_verdict:<{resid_width}}  {status}'
        )
    return '\n'.join(lines)


def _load(args: argparse.Namespace, notes: list[str]) -> tuple[Any, int]:
    """Load the data; ``--instruments`` channels come last among the inputs.

    Returns the data set and the number of instrument columns appended; lines
    about what ``--allow-gaps`` left out of a data file go into ``notes``.
    """
    from maglev_ros import sysid
    from maglev_ros.bags import is_bag_path, load_bag_dataset

    if is_bag_path(args.data):
        if not args.output:
            raise UsageError(
                f'{args.data} is a bag: choose channels with --output TOPIC:FIELD '
                '(and --input); maglev-bag2data --topics lists them'
            )
        data = load_bag_dataset(
            args.data,
            outputs=args.output,
            inputs=list(args.input) + list(args.instruments),
            Ts=args.ts,
            allow_gaps=args.allow_gaps,
            tolerance=args.tolerance,
        )
        return data, len(args.instruments)

    def load(**chosen: Any) -> Any:
        options = {
            'rows': tuple(args.rows) if args.rows else None,
            'outputs': args.outputs.split(',') if args.outputs else None,
            'inputs': args.inputs.split(',') if args.inputs else None,
        }
        options.update(chosen)
        return sysid.load_data(
            args.data, Ts=args.ts, matrix=args.matrix, allow_gaps=args.allow_gaps,
            notes=notes, **options,
        )  # fmt: skip

    return _file_with_instruments(args, load) if args.instruments else (load(), 0)


def _file_with_instruments(args: argparse.Namespace, load: Any) -> tuple[Any, int]:
    """Load a data file with the ``--instruments`` channels appended as the last inputs.

    Returns the data set and the number of instrument columns appended.
    """
    path = Path(args.data)
    specs = list(args.instruments)
    if args.rows:
        try:
            rows = [int(text) for text in specs]
        except ValueError:
            raise UsageError(
                f'--instruments with --rows takes rows of {args.matrix} counted from 1, '
                f'got {specs}'
            ) from None
        data = load(rows=(args.rows[0], list(args.rows[1]) + rows))
        keep = data.nu - len(rows)
        names = list(data.input_names)
        for k, row in enumerate(rows):  # an unnamed matrix: the row, not a made-up input name
            if names[keep + k] == f'u{keep + k + 1}':
                names[keep + k] = f'{args.matrix} row {row}'
        return dataclasses.replace(data, input_names=tuple(names)), len(rows)
    if path.suffix.lower() == '.csv':
        inputs = args.inputs.split(',') if args.inputs else None
        if inputs is None:
            raise UsageError('--instruments with a CSV file needs --inputs (the input columns)')
        return load(inputs=inputs + specs), len(specs)
    data = load()
    variables: dict[str, Any] = {}
    if path.suffix.lower() == '.npz':
        with np.load(path, allow_pickle=False) as npz:
            variables = {k: npz[k] for k in npz.files if k in specs}
    elif path.suffix.lower() == '.mat':
        from scipy.io import loadmat

        variables = loadmat(path, variable_names=specs)
    columns = []
    for name in specs:
        if name not in variables:
            raise UsageError(f'--instruments: {path.name} has no variable {name!r}')
        value = np.asarray(variables[name], dtype=float)
        value = value.reshape(value.shape[0], -1) if value.shape[0] == data.N else value.T
        if value.ndim != 2 or value.shape[0] != data.N:
            raise UsageError(
                f'--instruments: variable {name!r} has shape {np.shape(variables[name])}, '
                f'expected ({data.N},) or ({data.N}, k) like the data'
            )
        columns.append(value)
    from maglev_ros import sysid

    z = np.hstack(columns)
    combined = sysid.IdData(
        data.y,
        np.hstack([data.u, z]),
        data.Ts,
        data.output_names,
        list(data.input_names)
        + [
            name if block.shape[1] == 1 else f'{name}_{k + 1}'
            for name, block in zip(specs, columns, strict=True)
            for k in range(block.shape[1])
        ],
        data.output_units,
        list(data.input_units) + [''] * z.shape[1],
        t0=data.t0,
    )
    return combined, z.shape[1]


def _split_instruments(data: Any, count: int) -> tuple[Any, Any]:
    """Split the last ``count`` inputs off as instruments: ``(data, z (N, count) or None)``."""
    if not count:
        return data, None
    keep = data.nu - count
    return data.select(inputs=range(keep)), data.u[:, keep:]


def _write_plots(result: Any, directory: Path) -> tuple[list[Path], str]:
    """Write the residual, compare and Bode plots; return the files and a note (or '')."""
    from maglev_ros import sysid

    directory.mkdir(parents=True, exist_ok=True)
    shown = [r for r in result.rows if r.validated is not None and r.validated.is_stable]
    ahead = [r for r in result.rows if r.validated is not None and r.status != 'failed']
    written = []
    val = result.validation
    for index, row in enumerate(result.rows, start=1):
        if row.residuals is not None:
            written.append(
                sysid.resid_plot(
                    row.residuals,
                    directory / f'resid_{index}_{row.structure}.png',
                    val.output_names,
                    val.input_names,
                    model_label=row.label + (' (reduced)' if row.status == 'reduced' else ''),
                )
            )
    if shown and result.horizon is None:
        labels = [r.label + (' (reduced)' if r.status == 'reduced' else '') for r in shown]
        models = [r.validated for r in shown]
        written.append(
            sysid.compare_plot(val, models, directory / 'compare.png', labels, None, result.ic)
        )
    if ahead:
        labels = [r.label + (' (reduced)' if r.status == 'reduced' else '') for r in ahead]
        name = 'compare.png' if result.horizon is not None else 'compare_kstep.png'
        written.append(
            sysid.compare_plot(
                val,
                [r.validated for r in ahead],
                directory / name,
                labels,
                result.kstep,
                result.ic,
            )  # fmt: skip
        )
    if ahead:
        labels = [r.label + (' (reduced)' if r.status == 'reduced' else '') for r in ahead]
        written.append(
            sysid.bode_plot([r.validated for r in ahead], directory / 'bode.png', labels)
        )
    note = '' if written else f'no plots written into {directory}: no model was fitted'
    return written, note


def run(args: argparse.Namespace) -> int:
    """Execute a parsed command line; raise ``ValueError`` on bad input.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments of :func:`build_parser`.

    Returns
    -------
    int
        Exit status: 0 every model usable, 1 some model not usable.
    """
    from maglev_ros import sysid
    from maglev_ros.cli.progress import progress_bar
    from maglev_ros.sysid.workflow import ModelSpec, check_channels, identify, offset_hints

    if args.ts is not None and not 0 < args.ts < float('inf'):
        raise UsageError(
            f'--ts must be a positive sample time in seconds, a finite number, got {args.ts}'
        )
    if args.max_iter is not None and args.max_iter < 1:
        raise UsageError(f'--max-iter must be >= 1, got {args.max_iter}')
    for option, directory in (('--plot', args.plot), ('--save', args.save)):
        if directory:
            check_output_dir(option, directory)
    from .sysid_extra import check_arguments, extend_single, filtered, run_several, run_sindy

    check_arguments(args)
    if args.sindy:
        return run_sindy(args, _plain)
    if len(args.data) > 1:
        return run_several(args, _load, _plain, _requested(args))
    args.data = args.data[0]
    specs = _requested(args)
    if not specs and not args.select and not args.narx:
        raise UsageError(
            'no model requested: give --arx, --iv, --armax, --oe, --bj, --spec, --narx or --select'
        )
    split_text = str(args.split)
    try:
        split: float | int = float(split_text) if '.' in split_text else int(split_text)
    except ValueError:
        raise UsageError(
            f'--split must be a fraction such as 0.5 or a sample count such as '
            f'12500, got {split_text!r}'
        ) from None
    notes: list[str] = []
    data, n_instruments = _load(args, notes)
    if n_instruments and not any(spec.structure == 'iv' for spec in specs):
        raise UsageError('--instruments are used by --iv only: add --iv NA NB NK')
    raw = _split_instruments(data, n_instruments)[0]
    check_channels(raw)  # before detrending: a constant input is named with its value
    hints = (*notes, *(() if args.detrend else offset_hints(raw)))
    if args.detrend:
        data = data.detrend(args.detrend)
    data = filtered(args, data)
    if args.decimate != 1:
        data = data.decimate(args.decimate)
    est, val = data.split(split)
    est, instruments = _split_instruments(est, n_instruments)
    val, val_instruments = _split_instruments(val, n_instruments)
    summary: dict[str, Any] = {
        'data': {
            'file': str(args.data),
            'N': data.N,
            'ny': data.ny,
            'nu': est.nu,
            'Ts': data.Ts,
            'n_estimation': est.N,
            'n_validation': val.N,
            'outputs': list(data.output_names),
            'inputs': list(est.input_names),
            'output_units': list(data.output_units),
            'input_units': list(est.input_units),
            'instruments': list(data.input_names[est.nu :]),
        },
        'hints': list(hints),
        'models': [],
    }
    if args.select:
        na_max, nb_max, nk_max = args.select_max
        search = sysid.arxstruc(
            est, val, range(1, na_max + 1), range(1, nb_max + 1), range(1, nk_max + 1)
        )
        best = sysid.selstruc(search, args.select)
        summary['selection'] = {
            'criterion': args.select,
            'na': best[0],
            'nb': best[1],
            'nk': best[2],
            'candidates': len(search.loss),
        }
        specs.append(ModelSpec('arx', {'na': best[0], 'nb': best[1], 'nk': best[2]}))
    quiet = args.quiet or args.json
    with progress_bar(len(specs), 'identification', 'models', quiet) as bar:
        started = []

        def step(label: str, k: int, loss: float) -> None:
            if k == 0:  # a new model starts: the previous one is done
                bar.update(1 if started else 0)
                started.append(label)
                bar.set_postfix_str(label)
            else:
                bar.set_postfix_str(f'{label}: iteration {k}, loss {loss:.3g}')

        result = identify(
            est, val, specs, args.horizon, args.ic, args.max_iter, step, hints, instruments,
            val_instruments,
        )  # fmt: skip
        bar.update(1 if started else 0)
    what = 'simulation' if args.horizon is None else f'{args.horizon}-step prediction'
    for row in result.rows:
        entry = {} if row.model is None else sysid.model_to_dict(row.model)
        entry.update(
            {
                'label': row.label,
                'structure': entry.get('structure', row.structure),
                'status': row.status,
                'reason': row.reason,
                'notes': list(row.notes),
                'std': None if row.model is None or row.model.std is None else row.model.std,
                'fit_estimation': row.fit_estimation,
                'fit_validation': row.fit_validation,
                'prediction_fit': row.prediction_fit,
                'fpe': None if row.model is None else row.model.report.fpe,
                'mse': None if row.model is None else row.model.report.mse,
                'kstep_horizon': row.kstep,
                'kstep_estimation': row.kstep_estimation,
                'kstep_validation': row.kstep_validation,
                'usable': row.usable,
                'residuals': row.residual_verdict,
                'residuals_white': None if row.residuals is None else row.residuals.white,
                'residuals_independent': (
                    None if row.residuals is None else row.residuals.independent
                ),
                'residuals_summary': None if row.residuals is None else row.residuals.summary(),
            }
        )
        if row.validated is not None and row.validated is not row.model:  # reduced
            entry['validated'] = sysid.model_to_dict(row.validated)
        summary['models'].append(entry)
    feedback = None if result.feedback is None else result.feedback.as_dict()
    summary['closed_loop'] = result.closed_loop
    summary['feedback'] = feedback
    summary['kstep_horizon'] = result.kstep
    summary['fit_kind'] = what
    warnings = [] if feedback is None or not feedback['closed_loop'] else [feedback['summary']]
    if feedback is not None and feedback['closed_loop']:
        warnings.append(feedback['advice'])
    summary['warnings'] = warnings
    written, plot_note = _write_plots(result, Path(args.plot)) if args.plot else ([], '')
    extra_texts, extra_written, extra_status = extend_single(args, est, val, result, summary)
    written += extra_written
    exit_status = max(result.exit_status, extra_status)
    if args.save:
        Path(args.save).mkdir(parents=True, exist_ok=True)
        for index, row in enumerate(result.rows, start=1):
            if row.model is not None:
                sysid.save_model(
                    row.model, Path(args.save) / f'model_{index}_{row.structure}.json'
                )
    summary['exit_status'] = exit_status
    if plot_note:
        summary['warnings'].append(plot_note)
    if args.json:
        print(json.dumps(_plain(summary), indent=1))
        return exit_status
    header = (
        f'{PROG}: {data.N} samples of {data.ny} output(s), {est.nu} input(s), '
        f'Ts = {data.Ts:g} s; estimation {est.N}, validation {val.N}'
    )
    if 'selection' in summary:
        s = summary['selection']
        header += (
            f'\nOrder search ({s["criterion"]}, {s["candidates"]} candidates): '
            f'na={s["na"]} nb={s["nb"]} nk={s["nk"]}'
        )
    if summary['data']['instruments']:
        header += '\nInstruments of --iv: ' + ', '.join(summary['data']['instruments'])
    channels = ', '.join(
        f'{name} [{unit}]' if unit else name
        for name, unit in zip(
            [*data.output_names, *est.input_names],
            [*data.output_units, *est.input_units],
            strict=True,
        )
    )
    header += f'\nChannels (outputs, then inputs): {channels}'
    print(header)
    for warning in warnings:
        print(f'warning: {warning}')
    for hint in hints:
        print(f'hint: {hint}')
    for row in result.rows:
        print('\n' + _row_text(row, what, args.ic))
    for text in extra_texts:
        print('\n' + text)
    if result.rows:
        print('\n' + _summary_table(result, what))
    for path in written:
        print(f'wrote {path}')
    if plot_note:
        print(plot_note)
    return exit_status


def main(argv: list[str] | None = None) -> int:
    """Run ``maglev-sysid``; return the exit status.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 every model usable, 1 some model not usable, 2 bad input.
    """
    return run_command(PROG, build_parser(), _run_quietly, argv)


def _run_quietly(args: argparse.Namespace) -> int:
    limit_blas_threads(1)  # small solves: see limit_blas_threads
    with np.errstate(all='ignore'):
        return run(args)


if __name__ == '__main__':
    raise SystemExit(main())
