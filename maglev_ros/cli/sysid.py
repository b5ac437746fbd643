"""``maglev-sysid``: identify polynomial models from input/output data files.

The lab's MATLAB workflow (``iddata``, ``detrend``, ``idfilt``, ``arx``, ``iv4``,
``armax``, ``oe``, ``bj``, ``compare``, ``resid``) on the command line::

    maglev-sysid data.mat --rows 1 4 --ts 2e-4 --detrend --arx 7 9 1 --iv 7 9 1
    maglev-sysid data.mat --rows 1 4 --ts 2e-4 --armax 5 5 3 1 --plot plots/

Exit status: 0 on success, 2 on bad input (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from .usage import Parser, UsageError, limit_blas_threads, run_command

PROG = 'maglev-sysid'
STRUCTURES = {'arx': 3, 'iv': 3, 'armax': 4, 'oe': 3, 'bj': 5}


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
    )
    p.add_argument(
        'data',
        help='data file (.npz, .csv or MATLAB .mat, v7 or older) or a '
        'rosbag2 bag directory (then choose channels with --output/--input)',
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
        help='remove means (default) or linear trends before estimation',
    )
    p.add_argument(
        '--filter',
        nargs=2,
        type=float,
        metavar=('LOW', 'HIGH'),
        help='Butterworth pass band in Hz (LOW 0: low-pass), like idfilt',
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
    p.add_argument('--json', action='store_true', help='print a JSON result instead of text')
    p.add_argument('--plot', metavar='DIR', help='write compare/resid/bode PNGs into DIR')
    p.add_argument('--save', metavar='DIR', help='save each model as JSON into DIR')
    return p


def _spec_models(path: str) -> list[tuple[str, dict[str, Any]]]:
    import yaml

    spec_path = Path(path)
    if not spec_path.is_file():
        raise UsageError(f'spec file {path!r} does not exist')
    try:
        spec = yaml.safe_load(spec_path.read_text())
    except yaml.YAMLError as exc:
        raise UsageError(f'spec file {path!r} is not valid YAML: {exc}'.splitlines()[0]) from None
    models = spec.get('models') if isinstance(spec, dict) else None
    if not isinstance(models, list) or not models:
        raise UsageError(f'spec file {path!r} needs a non-empty "models" list')
    out = []
    allowed = {
        'arx': {'na', 'nb', 'nk'},
        'iv': {'na', 'nb', 'nk'},
        'armax': {'na', 'nb', 'nc', 'nk'},
        'oe': {'nb', 'nf', 'nk'},
        'bj': {'nb', 'nc', 'nd', 'nf', 'nk'},
    }
    for k, entry in enumerate(models):
        if not isinstance(entry, dict) or 'structure' not in entry:
            raise UsageError(f'spec model {k + 1} needs a "structure" field')
        structure = str(entry['structure']).lower().replace('iv4', 'iv')
        if structure not in allowed:
            raise UsageError(f'spec model {k + 1}: unknown structure {entry["structure"]!r}')
        orders = {key: v for key, v in entry.items() if key != 'structure'}
        unknown = set(orders) - allowed[structure]
        if unknown:
            raise UsageError(f'spec model {k + 1} ({structure}): unknown orders {sorted(unknown)}')
        out.append((structure, orders))
    return out


def _requested(args: argparse.Namespace) -> list[tuple[str, dict[str, Any]]]:
    names = {
        'arx': ('na', 'nb', 'nk'),
        'iv': ('na', 'nb', 'nk'),
        'armax': ('na', 'nb', 'nc', 'nk'),
        'oe': ('nb', 'nf', 'nk'),
        'bj': ('nb', 'nc', 'nd', 'nf', 'nk'),
    }
    out = []
    for structure, keys in names.items():
        for values in getattr(args, structure) or []:
            out.append((structure, dict(zip(keys, values, strict=True))))
    if args.spec:
        out += _spec_models(args.spec)
    return out


def _fit(structure: str, orders: dict[str, Any], data: Any) -> Any:
    from maglev_ros import sysid

    nk = orders.get('nk', 1)
    if structure == 'arx':
        return sysid.arx(data, orders['na'], orders['nb'], nk)
    if structure == 'iv':
        return sysid.iv4(data, orders['na'], orders['nb'], nk)
    if structure == 'armax':
        return sysid.armax(data, orders['na'], orders['nb'], orders['nc'], nk)
    if structure == 'oe':
        return sysid.oe(data, orders['nb'], orders['nf'], nk)
    return sysid.bj(data, orders['nb'], orders['nc'], orders['nd'], orders['nf'], nk)


def _label(model: Any) -> str:
    o = model.orders
    if o.ny == 1 and o.nu == 1:
        text = o.describe().replace('  ', ' ').replace('=', '')
        return f'{model.structure} {text}'
    return f'{model.structure} {o.ny}x{o.nu}'


def run(args: argparse.Namespace) -> int:
    """Execute a parsed command line; raise ``ValueError`` on bad input."""
    from maglev_ros import sysid

    if args.ts is not None and not args.ts > 0:
        raise UsageError(f'--ts must be a positive sample time in seconds, got {args.ts}')
    models_requested = _requested(args)
    if not models_requested and not args.select:
        raise UsageError(
            'no model requested: give --arx, --iv, --armax, --oe, --bj, --spec or --select'
        )
    split_text = str(args.split)
    try:
        split: float | int = float(split_text) if '.' in split_text else int(split_text)
    except ValueError:
        raise UsageError(
            f'--split must be a fraction such as 0.5 or a sample count such as '
            f'12500, got {split_text!r}'
        ) from None
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
            inputs=args.input,
            Ts=args.ts,
            allow_gaps=args.allow_gaps,
            tolerance=args.tolerance,
        )
    else:
        data = sysid.load_data(
            args.data,
            Ts=args.ts,
            rows=tuple(args.rows) if args.rows else None,
            matrix=args.matrix,
            outputs=args.outputs.split(',') if args.outputs else None,
            inputs=args.inputs.split(',') if args.inputs else None,
        )
    if args.detrend:
        data = data.detrend(args.detrend)
    if args.filter:
        data = data.filter(tuple(args.filter), args.filter_order, args.zero_phase)
    if args.decimate != 1:
        data = data.decimate(args.decimate)
    est, val = data.split(split)
    result: dict[str, Any] = {
        'data': {
            'file': str(args.data),
            'N': data.N,
            'ny': data.ny,
            'nu': data.nu,
            'Ts': data.Ts,
            'n_estimation': est.N,
            'n_validation': val.N,
            'outputs': list(data.output_names),
            'inputs': list(data.input_names),
        },
        'models': [],
    }
    if args.select:
        na_max, nb_max, nk_max = args.select_max
        search = sysid.arxstruc(
            est, val, range(1, na_max + 1), range(1, nb_max + 1), range(1, nk_max + 1)
        )
        best = sysid.selstruc(search, args.select)
        result['selection'] = {
            'criterion': args.select,
            'na': best[0],
            'nb': best[1],
            'nk': best[2],
            'candidates': len(search.loss),
        }
        models_requested.append(('arx', {'na': best[0], 'nb': best[1], 'nk': best[2]}))
    models, texts = [], []
    for structure, orders in models_requested:
        model = _fit(structure, orders, est)
        models.append(model)
        fit_est = sysid.compare(model, est, args.horizon, args.ic).fit
        fit_val = sysid.compare(model, val, args.horizon, args.ic).fit
        analysis = sysid.resid(model, val)
        entry = sysid.model_to_dict(model)
        entry.update(
            {
                'std': None if model.std is None else model.std.tolist(),
                'fit_estimation': fit_est.tolist(),
                'fit_validation': fit_val.tolist(),
                'fpe': model.report.fpe,
                'mse': model.report.mse.tolist(),
                'residuals_white': analysis.white,
                'residuals_independent': analysis.independent,
            }
        )
        entry.pop('covariance', None)
        result['models'].append(entry)
        what = 'simulation' if args.horizon is None else f'{args.horizon}-step prediction'
        texts.append(
            f'{model}\n  Compare ({what}, ic={args.ic}): fit to estimation data '
            + ', '.join(f'{f:.2f}%' for f in fit_est)
            + '; validation data '
            + ', '.join(f'{f:.2f}%' for f in fit_val)
            + f'\n  Validation {analysis.summary()}'
        )
        if args.plot:
            Path(args.plot).mkdir(parents=True, exist_ok=True)
            index = len(models)
            sysid.resid_plot(
                analysis,
                Path(args.plot) / f'resid_{index}_{structure}.png',
                val.output_names,
                val.input_names,
            )
        if args.save:
            Path(args.save).mkdir(parents=True, exist_ok=True)
            sysid.save_model(model, Path(args.save) / f'model_{len(models)}_{structure}.json')
    if args.plot:
        labels = [_label(m) for m in models]
        sysid.compare_plot(
            val, models, Path(args.plot) / 'compare.png', labels, args.horizon, args.ic
        )
        sysid.bode_plot(models, Path(args.plot) / 'bode.png', labels)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        header = (
            f'{PROG}: {data.N} samples of {data.ny} output(s), {data.nu} input(s), '
            f'Ts = {data.Ts:g} s; estimation {est.N}, validation {val.N}'
        )
        if 'selection' in result:
            s = result['selection']
            header += (
                f'\nOrder search ({s["criterion"]}, {s["candidates"]} candidates): '
                f'na={s["na"]} nb={s["nb"]} nk={s["nk"]}'
            )
        print(header)
        for text in texts:
            print('\n' + text)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run ``maglev-sysid``; return the exit status (2 on bad input).

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.
    """
    return run_command(PROG, build_parser(), _run_quietly, argv)


def _run_quietly(args: argparse.Namespace) -> int:
    limit_blas_threads(1)  # small solves: see limit_blas_threads
    with np.errstate(all='ignore'):
        return run(args)


if __name__ == '__main__':
    sys.exit(main())
