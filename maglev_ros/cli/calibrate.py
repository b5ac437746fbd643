r"""``maglev-calibrate``: calibrate a board's physical model from its bags.

Static mode: bags recorded with the levitating magnet absent or held fixed
(for example ``maglev-lab --magnet absent`` and ``--magnet fixed``); the
chosen physics parameters are estimated from the field against the coil
currents. Dynamic mode: bags recorded while the magnet levitates under
feedback with an excitation added (``--magnet free``); a linear grey-box
(the model linearised at the parameters' equilibrium, its Kalman predictor)
is fitted by prediction error, which gives the magnet's mass and
polarisation. Either writes a parameter file that loads like ``maggy_v2.yaml``::

    maglev-calibrate absent/ fixed/ --params maggy_v2 \
        --free 'coil*.gain' 'sensor*.offset_*' --out static.yaml
    maglev-calibrate levitating/ --params static.yaml \
        --free magnet.mass magnet.polarization --out myboard.yaml

Names accept shell patterns; ``--list`` shows every parameter. Where the
magnet was comes from a bag's run metadata (``magnet``: absent, fixed or
free), or from ``--magnet``, or from a suffix ``BAG@absent`` / ``BAG@fixed``
/ ``BAG@free``. Static and levitation bags go in separate runs.
Data files (``.npz``, ``.mat``, ``.csv``, as ``maglev-sysid`` reads them and
``maglev-bag2data`` writes them) work like bags: their channels are picked by
name (``Bx_0``, ``By_0``, ``Bz_0``, ..., ``i0`` .. ``i3`` by default, or the
names given with ``--output``/``--input``); say where the magnet was with
``--magnet`` or ``FILE@free``.

Results are checked (:mod:`maglev_ros.greybox.verdict`): a parameter at a
bound, a calibrated set that validates worse than the nominal one, an
undetermined sensor delay, two estimates correlated above 0.99, unidentified
parameters or a diverging predictor each give a warning and the status
``partly calibrated`` or ``not calibrated``; then no parameter file is
written. Exit status: 0 calibrated, 1 partly or not calibrated (the warnings
say why), 2 on bad input (one line on stderr).
"""

from __future__ import annotations

import argparse
import datetime
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from maglev_ros.topics import current_channel, field_channel, field_topic

from .bag2data import add_channel_arguments
from .usage import (
    Parser,
    UsageError,
    check_output_file,
    limit_blas_threads,
    positive_float,
    run_command,
)

__all__ = ['build_parser', 'main', 'default_channels', 'parse_bounds']

PROG = 'maglev-calibrate'
AXES = ('x', 'y', 'z')


def default_channels(sensors: Sequence[int], coils: int) -> tuple[list[str], list[str]]:
    """Return the channel specs of the field (outputs) and the coil currents (inputs) of a run.

    Parameters
    ----------
    sensors : sequence of int
        The 3-axis sensors recorded.
    coils : int
        Number of solenoids.

    Returns
    -------
    outputs, inputs : list of str
        ``B{axis}_{k}=maglev/sensor_{k}/field:magnetic_field.{axis}`` and
        ``i{j}=maglev/currents:effort[{j}]``.
    """
    outputs = [f'B{a}_{k}={field_channel(k, a)}' for k in sensors for a in AXES]
    inputs = [f'i{j}={current_channel(j)}' for j in range(coils)]
    return outputs, inputs


def parse_bounds(text: str) -> tuple[str, float, float]:
    """Argparse type: ``NAME=LOWER:UPPER`` in SI units.

    Parameters
    ----------
    text : str
        ``NAME=LOWER:UPPER`` in SI units.
    """
    name, sep, rest = text.partition('=')
    lower, sep2, upper = rest.partition(':')
    try:
        if not (sep and sep2 and name):
            raise ValueError
        return name, float(lower), float(upper)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'expected NAME=LOWER:UPPER (SI units), got {text!r}'
        ) from None


def _split_fraction(text: str) -> float:
    value = positive_float(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f'must be a fraction in (0, 1), got {text!r}')
    return value


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-calibrate``."""
    p = Parser(
        prog=PROG,
        description='Calibrate the physics parameters of a board from bags recorded with '
        'the magnet absent or held fixed (static calibration) or levitating under feedback '
        'with an excitation (dynamic calibration: mass, polarisation).',
    )
    p.add_argument(
        'bags',
        nargs='*',
        metavar='BAG',
        help='bag directories; BAG@absent, BAG@fixed or BAG@free (levitating) says where '
        'the magnet was '
        '(default: the bag metadata, else --magnet)',
    )
    p.add_argument(
        '--params', default='maggy_v2', help='nominal parameter set: preset or YAML path'
    )
    p.add_argument(
        '--free',
        nargs='+',
        action='extend',
        default=[],
        metavar='NAME',
        help="parameters to estimate (shell patterns, e.g. 'coil*.gain' 'sensor*.offset_*')",
    )
    p.add_argument(
        '--bounds',
        type=parse_bounds,
        action='append',
        default=[],
        metavar='NAME=LO:HI',
        help='bounds of a parameter in SI units (must contain the nominal value)',
    )
    p.add_argument('--out', metavar='FILE.yaml', help='write the calibrated parameter file')
    p.add_argument(
        '--plot',
        metavar='FILE.png',
        help='measured vs model plot (default: next to --out; one file per bag)',
    )
    p.add_argument(
        '--sensors',
        type=int,
        nargs='+',
        metavar='K',
        help='sensors recorded (default: those of the parameter set that the first bag has)',
    )
    p.add_argument(
        '--magnet',
        choices=('absent', 'fixed', 'free'),
        help='where the magnet was, for bags whose metadata does not say (free: levitating)',
    )
    p.add_argument(
        '--split',
        type=_split_fraction,
        default=0.5,
        help='fraction of each bag used for estimation; the rest validates (default 0.5)',
    )
    p.add_argument(
        '--delay',
        type=int,
        metavar='SAMPLES',
        help='sensor delay in samples (default: estimated per bag)',
    )
    p.add_argument(
        '--frozen-run',
        type=int,
        default=3,
        metavar='N',
        help='leave out a sensor frozen for N or more identical readings while the '
        'currents change (default 3; 0 keeps every reading)',
    )
    p.add_argument(
        '--hold-pose',
        action='store_true',
        help='do not estimate where a fixed magnet is held (use the nominal equilibrium)',
    )
    p.add_argument(
        '--process-noise',
        type=positive_float,
        default=1e-3,
        metavar='AMPS',
        help='dynamic mode: input disturbance level of the Kalman predictor, A rms (default 1e-3)',
    )
    p.add_argument(
        '--form',
        choices=('linear', 'nonlinear'),
        default='linear',
        help='dynamic mode: linear grey-box (the linearised model, as idgrey) or the full '
        'nonlinear model (as nlgreyest), each with its Kalman predictor (default linear)',
    )
    p.add_argument(
        '--measurement',
        choices=('raw', 'board'),
        default='raw',
        help='dynamic mode: what the field channels are: raw (the sensors, as the physics '
        'model gives them; default) or board (a V4x PC-control firmware: power-up baseline '
        'and coil feedthrough removed, x/y low-pass). Chosen here, never guessed from the data',
    )
    p.add_argument(
        '--board-feedthrough',
        nargs=6,
        type=float,
        metavar='T_PER_A',
        help='with --measurement board: the processed Bx, By, Bz per ampere of the x pair and '
        'of the y pair, row by row (T/A), measured without the magnet (default: the '
        "records' metadata, which maglev-lab --firmware v4x_pc writes; else the firmware's "
        'compensation taken as exact)',
    )
    p.add_argument('--list', action='store_true', help='list the parameters and exit')
    p.add_argument(
        '--ts',
        type=positive_float,
        metavar='SECONDS',
        help='sample time (default: estimated from the first output stamps)',
    )
    add_channel_arguments(p)
    return p


def _say(line: str) -> None:
    print(line, flush=True)


def _list(vector) -> int:
    print(f'{"parameter":<28}{"unit":<6}{"nominal":>14}{"lower":>14}{"upper":>14}  meaning')
    for s in vector.specs:
        print(
            f'{s.name:<28}{s.unit:<6}{s.nominal:>14.6g}{s.lower:>14.6g}{s.upper:>14.6g}  '
            f'{s.description}'
        )
    print('pose{e}.x|y|z|alpha|beta: where fixed-magnet bag e held the magnet (estimated)')
    return 0


def _bag_and_magnet(text: str, default: str | None) -> tuple[str, str | None]:
    bag, sep, mode = text.rpartition('@')
    if sep and mode in ('absent', 'fixed', 'free'):
        return bag, mode
    return text, default


def _recorded_magnet(metadata: dict) -> str | None:
    """Where the magnet was, from run metadata (``magnet`` or ``<node>.magnet``)."""
    for key, value in metadata.items():
        if key == 'magnet' or key.endswith('.magnet'):
            text = str(value).strip()
            if text:
                return text
    return None


def _bag_sensors(bag: str, count: int) -> list[int]:
    """Sensors of the parameter set whose field topic the bag (or data file) has."""
    from maglev_ros.bags import BagReader

    if Path(bag).suffix.lower() in DATA_SUFFIXES and Path(bag).is_file():
        from maglev_ros.sysid import load_data

        if Path(bag).suffix.lower() == '.csv':
            with open(bag) as fh:
                names = [h.split('[')[0].strip() for h in fh.readline().split(',')]
        else:
            data = load_data(bag, Ts=1.0)
            names = [*data.output_names, *data.input_names]
        found = [k for k in range(count) if all(f'B{a}_{k}' in names for a in AXES)]
        if not found:
            raise UsageError(
                f'{bag}: no field channels Bx_k, By_k, Bz_k of sensors 0 to {count - 1}; '
                'name them with --output NAME (three per sensor) and --sensors'
            )
        return found

    with BagReader(bag) as reader:
        topics = reader.topics
    found = [k for k in range(count) if '/' + field_topic(k) in topics]
    if not found:
        raise UsageError(
            f'{bag}: no field topic of sensors 0 to {count - 1} (/{field_topic(0)}, ...); '
            f'its topics: {", ".join(sorted(topics))}'
        )
    return found


DATA_SUFFIXES = ('.npz', '.mat', '.csv')


def _channel_name(spec: str) -> str:
    """Return the channel name of a spec (``NAME=TOPIC:FIELD`` gives NAME; a plain name itself)."""
    return spec.partition('=')[0].strip() if '=' in spec else spec.strip()


def _file_data(path: str, args, outputs, inputs):
    """Read a data file (as maglev-sysid does) and pick the channels by name."""
    from maglev_ros.sysid import IdData, load_data

    out_names = [_channel_name(s) for s in outputs]
    in_names = [_channel_name(s) for s in inputs]
    notes: list[str] = []
    if Path(path).suffix.lower() == '.csv':
        data = load_data(
            path, Ts=args.ts, outputs=out_names, inputs=in_names, allow_gaps=args.allow_gaps,
            notes=notes,
        )  # fmt: skip
    else:
        data = load_data(path, Ts=args.ts, allow_gaps=args.allow_gaps, notes=notes)
        names = [*data.output_names, *data.input_names]
        columns = np.hstack([data.y, data.u])
        missing = [n for n in out_names + in_names if n not in names]
        if missing:
            raise UsageError(
                f'{path} has no channel {missing[0]!r} (its channels: {", ".join(names)}): '
                'name the field and current channels with --output NAME / --input NAME, or '
                'write the file with maglev-bag2data using the names '
                f'{", ".join(out_names[:3])}, ... and {", ".join(in_names[:2])}, ...'
            )
        pick = [names.index(n) for n in out_names + in_names]
        data = IdData(
            columns[:, pick[: len(out_names)]], columns[:, pick[len(out_names) :]], data.Ts,
            out_names, in_names,
        )  # fmt: skip
    for note in notes:
        _say(f'  {note}')
    return data, {}


def _experiment(bag: str, mode: str | None, args, sensors, outputs, inputs):
    from maglev_ros.bags import read_bag
    from maglev_ros.greybox import LevitationExperiment, StaticExperiment

    _say(f'reading {bag} ...')
    if Path(bag).suffix.lower() in DATA_SUFFIXES and Path(bag).is_file():
        data, metadata = _file_data(bag, args, outputs, inputs)
    else:
        if Path(bag).is_file():
            raise UsageError(
                f'{bag} is neither a bag directory nor a data file '
                f'({", ".join(DATA_SUFFIXES)}): convert it with maglev-bag2data or save it '
                'as .npz/.mat/.csv with the channels named'
            )
        ds = read_bag(
            bag,
            outputs,
            inputs,
            Ts=args.ts,
            allow_gaps=args.allow_gaps,
            tolerance=args.tolerance,
        )
        data, metadata = ds.data, ds.metadata
    magnet = mode or _recorded_magnet(metadata)
    if magnet == 'free' and 'board_feedthrough' in metadata:
        args.recorded_feedthrough.append((bag, metadata['board_feedthrough']))
    if magnet is None:
        raise UsageError(
            f'{bag}: the data do not say whether the magnet was absent, fixed or free '
            f'(levitating): give --magnet or {bag}@absent / {bag}@fixed / {bag}@free'
        )
    if magnet not in ('absent', 'fixed', 'free'):
        raise UsageError(
            f'{bag}: recorded with the magnet {magnet!r}; calibration needs it absent, '
            'held fixed or free (levitating)'
        )
    if magnet == 'free':
        exp = LevitationExperiment(
            u=data.u,
            y=data.y,
            name=f'{bag} (levitating)',
            Ts=data.Ts,
            sensors=tuple(sensors),
        )
        idle = exp.coils_idle()
        if idle is not None:
            raise UsageError(
                f'{bag}: no coil current changes from {idle[0]:.3f} s on for {idle[1]:.3f} s: '
                'the loop was not acting (the magnet lost, or not yet levitating), so this is '
                'not a record of a levitating magnet; record one where the loop held the '
                'magnet throughout'
            )
        _say(
            f'  {exp.samples} samples at {1 / data.Ts:.6g} Hz, magnet levitating, '
            f'sensors {", ".join(map(str, sensors))}'
        )
        return exp
    exp = StaticExperiment(
        u=data.u,
        y=data.y,
        magnet=magnet,
        name=f'{bag} (magnet {magnet})',
        Ts=data.Ts,
        sensors=tuple(sensors),
    )
    _say(
        f'  {exp.samples} samples at {1 / data.Ts:.6g} Hz, magnet {magnet}, '
        f'sensors {", ".join(map(str, sensors))}'
    )
    return exp


def _board_pairs(args, sensors: int):
    """Return the pairs' measured feedthrough for ``--measurement board``, T/A (None: exact)."""
    from maglev_ros.hardware.v4x_pc_feedthrough import PairFeedthrough

    if args.measurement != 'board':
        return None
    if args.board_feedthrough is not None:
        values, source = args.board_feedthrough, '--board-feedthrough'
    elif args.recorded_feedthrough:
        if len({str(v) for _, v in args.recorded_feedthrough}) > 1:
            raise UsageError(
                'the records carry different board feedthroughs (each session measures its '
                'own): calibrate them one at a time, or give --board-feedthrough'
            )
        values, source = args.recorded_feedthrough[0][1], 'the record'
    else:
        _say(
            "board feedthrough: the firmware's compensation taken as exact (the records do "
            'not carry a measurement; maglev-lab --firmware v4x_pc measures it before the '
            'magnet is placed)'
        )
        return None
    if sensors != 1:
        raise UsageError(f'--measurement board reads one sensor, got {sensors}')
    try:
        pairs = PairFeedthrough.response_from(values)
    except ValueError as err:
        raise UsageError(f'{source}: {err}') from None
    r = 1e3 * pairs
    _say(
        f'board feedthrough from {source}: x pair into Bx {r[0, 0]:+.4f} mT/A, y pair into '
        f'By {r[1, 1]:+.4f} mT/A (Bz {r[2, 0]:+.4f}, {r[2, 1]:+.4f} mT/A)'
    )
    return pairs


def _header(args, cal, bags) -> list[str]:
    now = datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')
    lines = [
        f'Calibrated by {PROG} on {now} from {args.params}',
        f'bags: {", ".join(bags)}',
        (
            f'dynamic calibration (levitation data, {cal.form} grey-box, Kalman predictor)'
            if getattr(cal, 'form', None)
            else 'static calibration (field vs coil currents)'
        )
        + '; estimate +- standard deviation:',
    ]
    for name in cal.names:
        spec = cal.vector[name]
        lines.append(
            f'  {name} = {spec.display(cal.estimate[name])} +- {spec.display(cal.std[name])}'
            f' (nominal {spec.display(spec.nominal)})'
        )
    for u in cal.identifiability.unidentified:
        lines.append(f'  {u.line()}')
    for nom, new in zip(cal.validation_nominal, cal.validation_calibrated, strict=True):
        lines.append(
            f'validation RMS error {nom.experiment}: nominal {1e3 * nom.total_rms:.4g} mT, '
            f'calibrated {1e3 * new.total_rms:.4g} mT'
        )
    lines.append('coil gains appear as effective turns (solenoids.turns = nominal turns x gain)')
    return lines


def _run(args: argparse.Namespace) -> int:
    from maglev_ros.greybox import (
        LevitationExperiment,
        assess,
        calibrate_dynamic,
        calibrate_static,
        parameter_vector,
        write_parameters,
    )
    from maglev_ros.physics import load_parameters

    limit_blas_threads(1)  # small solves: see limit_blas_threads
    base = load_parameters(args.params)
    vector = parameter_vector(base)
    if args.list:
        return _list(vector)
    if not args.bags:
        raise UsageError(
            'give at least one BAG (recorded with the magnet absent, fixed or levitating)'
        )
    if not args.free:
        raise UsageError("choose parameters with --free (e.g. 'coil*.gain'); --list shows them")
    vector = vector.with_free(args.free)
    for name, lower, upper in args.bounds:
        vector = vector.with_bounds(name, lower, upper)
    if args.frozen_run < 0:
        raise UsageError(f'--frozen-run must be >= 0, got {args.frozen_run}')
    if args.delay is not None and args.delay < 0:
        raise UsageError(f'--delay must be >= 0 samples, got {args.delay}')
    if args.board_feedthrough is not None and args.measurement != 'board':
        raise UsageError('--board-feedthrough goes with --measurement board')
    if args.out and Path(args.out).suffix not in ('.yaml', '.yml'):
        raise UsageError(f'--out must name a .yaml file, got {args.out!r}')
    if args.out:
        check_output_file('--out', args.out)
    plot_path = args.plot or (str(Path(args.out).with_suffix('.png')) if args.out else None)
    if plot_path:
        check_output_file('--plot', plot_path)
    if (
        args.out
        and Path(args.params).is_file()
        and Path(args.out).resolve() == Path(args.params).resolve()
    ):
        raise UsageError(
            f'--out {args.out} is the nominal parameter file (--params): write the '
            'calibrated set to a new file, the nominal one stays as it is'
        )
    count = len(base.sensors)
    parsed = [_bag_and_magnet(text, args.magnet) for text in args.bags]
    sensors = args.sensors
    if sensors is None:
        if args.output:
            sensors = list(range(len(args.output) // 3))
        else:
            sensors = _bag_sensors(parsed[0][0], count)
    bad = [k for k in sensors if not 0 <= k < count]
    if bad:
        raise UsageError(f'--sensors {bad}: {base.name} has sensors 0 to {count - 1}')
    defaults = default_channels(sensors, base.solenoids.count)
    outputs = args.output or defaults[0]
    inputs = args.input or defaults[1]
    experiments, bags = [], []
    args.recorded_feedthrough = []
    for bag, mode in parsed:
        experiments.append(_experiment(bag, mode, args, sensors, outputs, inputs))
        bags.append(bag)
    levitating = [isinstance(e, LevitationExperiment) for e in experiments]
    if any(levitating) and not all(levitating):
        raise UsageError(
            'levitation bags (magnet free) and static bags (absent/fixed) go in separate '
            'runs: calibrate the static part first, then pass its file as --params'
        )
    if all(levitating):
        _say(
            f'dynamic calibration from levitation data ({args.form} grey-box, Kalman '
            f'predictor, {args.measurement} field)'
        )
        cal = calibrate_dynamic(
            vector,
            experiments,
            split=args.split,
            delay=args.delay,
            process_noise=args.process_noise,
            progress=_say,
            form=args.form,
            measurement=args.measurement,
            board_pairs=_board_pairs(args, len(sensors)),
        )
    else:
        if args.measurement != 'raw':
            raise UsageError(
                '--measurement board is for levitation data: with the magnet absent or '
                'fixed a processed board reports (nearly) nothing to calibrate against'
            )
        delays = None if args.delay is None else [args.delay] * len(experiments)
        cal = calibrate_static(
            vector,
            experiments,
            split=args.split,
            delays=delays,
            fit_pose=not args.hold_pose,
            progress=_say,
            frozen_run=args.frozen_run,
        )
    print()
    for line in cal.table():
        print(line)
    if cal.identifiability.unidentified:
        print('\nnot identified by these data (held at their nominal values):')
        for u in cal.identifiability.unidentified:
            print(f'  {u.line()}')
    if cal.correlated:
        print('\nstrongly correlated estimates (each is uncertain along their combination):')
        for a, b, r in cal.correlated:
            print(f'  {a} ~ {b}: r = {r:+.3f}')
    print(f'\nweighted residual per degree of freedom {cal.chi2_per_dof:.3f} (1 = noise level)')
    if getattr(cal, 'form', None):
        print(
            f'equilibrium height: nominal {1e3 * cal.z_eq[0]:.4f} mm, '
            f'calibrated {1e3 * cal.z_eq[1]:.4f} mm'
        )
        print('validation (data not used for estimation; one-step-ahead Kalman prediction):')
    else:
        print('validation (data not used for estimation):')
    for nom, new in zip(cal.validation_nominal, cal.validation_calibrated, strict=True):
        print(
            f'  {nom.experiment}: RMS error nominal {1e3 * nom.total_rms:.4g} mT, calibrated '
            f'{1e3 * new.total_rms:.4g} mT; mean fit nominal {nom.mean_fit:.1f} %, '
            f'calibrated {new.mean_fit:.1f} %'
        )
    verdict = assess(cal)
    print()
    for line in verdict.warnings:
        print(f'warning: {line}')
    print(f'status: {verdict.status}')
    if args.out and verdict.status == 'calibrated':
        params = cal.params.replace(name=Path(args.out).stem)
        path = write_parameters(params, args.out, _header(args, cal, bags))
        print(f'wrote     {path}')
    elif args.out:
        print(
            f'not written: {args.out} ({verdict.status}: the warnings above say what failed; '
            'the nominal parameters stay in use)'
        )
    plot = args.plot or (str(Path(args.out).with_suffix('.png')) if args.out else None)
    if plot:
        from maglev_ros.greybox.plots import calibration_plot

        for i, exp in enumerate(experiments):
            target = Path(plot)
            if len(experiments) > 1:
                kind = getattr(exp, 'magnet', 'free')
                target = target.with_name(f'{target.stem}_{i}_{kind}{target.suffix}')
            print(f'wrote     {calibration_plot(cal, i, target, Ts=exp.Ts)}')
    return verdict.exit_status


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``maglev-calibrate``; return the exit status (2 on bad input).

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments (default: the command line).
    """
    return run_command(PROG, build_parser(), _run, argv)


if __name__ == '__main__':
    sys.exit(main())
