"""``maglev-model``: equilibria, linearisation and simulation of the Maggy model.

Also ``ros2 run maglev_ros model``. Human-readable output by default,
``--json`` for machines. Bad input: exit status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence

import numpy as np

from .usage import Parser, UsageError, non_negative_float, positive_float, run_command

PROG = 'maglev-model'
__all__ = ['build_parser', 'main', 'simulation_figure']


def _state_assignments(text: str) -> dict[str, float]:
    from ..physics.model import STATE_NAMES

    out = {}
    for item in filter(None, (part.strip() for part in text.split(','))):
        name, sep, value = item.partition('=')
        name = name.strip()
        if not sep or name not in STATE_NAMES:
            raise argparse.ArgumentTypeError(
                f'expected NAME=VALUE with NAME in {", ".join(STATE_NAMES)}, got {item!r}'
            )
        try:
            out[name] = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{name}: not a number: {value!r}') from None
        if not np.isfinite(out[name]):
            raise argparse.ArgumentTypeError(f'{name}: must be finite, got {value!r}')
    return out


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-model``."""
    common = Parser(add_help=False)
    common.add_argument(
        '--params',
        default='maggy_v2',
        help='parameter set: maggy_v2, maggy_v4 or a YAML path (default maggy_v2)',
    )
    common.add_argument(
        '--model',
        default='fast',
        choices=('fast', 'accurate', 'filament'),
        help='field model (default fast)',
    )
    common.add_argument(
        '--torque',
        default='true',
        choices=('true', 'published'),
        help="torque: the rim forces' moment (true) or the reference code's "
        'expression (published)',
    )
    common.add_argument(
        '--kinematics',
        default='rigid',
        choices=('rigid', 'published'),
        help='rigid-body Euler kinematics (rigid) or the published shortcut',
    )
    common.add_argument(
        '--correction',
        default='auto',
        help='solenoid radius factor of the fast model: auto, none or a number',
    )
    common.add_argument('--json', action='store_true', help='machine-readable output')
    common.add_argument('--quiet', action='store_true', help='no progress display')

    parser = Parser(prog=PROG, description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='command', required=True, parser_class=Parser)
    sub.add_parser(
        'equilibria',
        parents=[common],
        help='heights where the centred magnet floats (normal and inverted)',
    )
    lin = sub.add_parser(
        'linearize', parents=[common], help='A, B, C, D about the first equilibrium'
    )
    lin.add_argument(
        '--reduced', action='store_true', help='print the 10-state model without yaw and yaw rate'
    )
    lin.add_argument(
        '--step', type=positive_float, default=1e-6, help='finite-difference step (default 1e-6)'
    )
    sim = sub.add_parser(
        'simulate', parents=[common], help='simulate from a perturbed equilibrium'
    )
    sim.add_argument('--duration', type=positive_float, default=1.0, help='simulated time, s')
    sim.add_argument('--rate', type=positive_float, default=5000.0, help='sample rate, Hz')
    sim.add_argument(
        '--perturb',
        type=_state_assignments,
        default={'z': 0.001},
        help='offsets from the equilibrium, e.g. "z=0.001,alpha=0.01" (default z=0.001)',
    )
    sim.add_argument(
        '--currents',
        type=float,
        nargs='+',
        metavar='A',
        help='constant solenoid currents x+ x- y+ y-, A (default 0)',
    )
    sim.add_argument(
        '--coil', action='store_true', help='coil dynamics (the currents are commands through L/R)'
    )
    sim.add_argument('--noise', type=non_negative_float, default=0.0, help='sensor noise, T rms')
    sim.add_argument('--seed', type=int, default=0, help='noise seed')
    sim.add_argument(
        '--no-crash-check',
        action='store_true',
        help='integrate through contact and the workspace limits',
    )
    sim.add_argument('--plot', metavar='PNG', help='write a plot of the trajectory')
    sim.add_argument('--csv', metavar='CSV', help='write t, state and readings per sample')
    return parser


def _model(args):
    from ..physics.model import make_model

    correction = args.correction
    if correction not in ('auto', 'none'):
        try:
            correction = float(correction)
        except ValueError:
            raise UsageError(
                f'--correction: expected auto, none or a number, got {args.correction!r}'
            ) from None
    return make_model(
        args.params,
        field=args.model,
        torque=args.torque,
        kinematics=args.kinematics,
        correction=correction,
    )


def _matrix_text(name: str, matrix: np.ndarray, rows, cols) -> str:
    width = 12
    lines = [
        f'{name} ({matrix.shape[0]} x {matrix.shape[1]}), rows: {", ".join(rows)}; '
        f'columns: {", ".join(cols)}'
    ]
    for row_name, row in zip(rows, matrix, strict=True):
        lines.append(f'  {row_name:>6} ' + ' '.join(f'{v:{width}.4e}' for v in row))
    return '\n'.join(lines)


def _equilibria(args) -> int:
    from ..physics.equilibria import find_equilibria

    model = _model(args)
    normal = find_equilibria(model)
    inverted = find_equilibria(model, inverted=True)
    if args.json:
        print(
            json.dumps(
                {
                    'params': model.params.name,
                    'model': args.model,
                    'correction': model.correction,
                    'equilibria': [{'z': e.z, 'dFz_dz': e.stiffness} for e in normal],
                    'inverted': [{'z': e.z, 'dFz_dz': e.stiffness} for e in inverted],
                },
                indent=2,
            )
        )
        return 0
    print(
        f'{model.params.name}: {args.model} model, solenoid radius factor {model.correction:.9f}'
    )
    for title, found in (('equilibria', normal), ('inverted (J -> -J)', inverted)):
        print(f'{title}:')
        if not found:
            print('  none')
        for e in found:
            kind = 'vertically stable' if e.vertically_stable else 'vertically unstable'
            print(f'  z = {e.z * 1e3:9.4f} mm   dFz/dz = {e.stiffness:10.3f} N/m   ({kind})')
    return 0


def _linearize(args) -> int:
    from ..physics.linearization import linearize

    model = _model(args)
    lin = linearize(model, step=args.step)
    full = lin
    if args.reduced:
        lin = lin.reduced()
    ranks = {
        'controllability': lin.controllability_rank(),
        'observability': lin.observability_rank(),
        'states': len(lin.states),
    }
    if args.json:
        print(
            json.dumps(
                {
                    'params': model.params.name,
                    'model': args.model,
                    'torque': args.torque,
                    'kinematics': args.kinematics,
                    'z_eq': float(full.x_eq[2]),
                    'correction': model.correction,
                    'step': lin.step,
                    'states': list(lin.states),
                    'inputs': list(lin.inputs),
                    'outputs': list(lin.outputs),
                    'A': lin.A.tolist(),
                    'B': lin.B.tolist(),
                    'C': lin.C.tolist(),
                    'D': lin.D.tolist(),
                    'poles': {'real': lin.poles.real.tolist(), 'imag': lin.poles.imag.tolist()},
                    'ranks': ranks,
                },
                indent=1,
            )
        )
        return 0
    np.set_printoptions(linewidth=200)
    print(
        f'{model.params.name}: {args.model} model, torque {args.torque}, kinematics '
        f'{args.kinematics}'
    )
    print(
        f'z_eq = {full.x_eq[2]:.9f} m, solenoid radius factor {model.correction:.9f}, '
        f'finite-difference step {lin.step:g}'
    )
    print(f'states:  {", ".join(lin.states)}')
    print(f'inputs:  {", ".join(lin.inputs)} (A)')
    print(f'outputs: {", ".join(lin.outputs)} (T)')
    print(_matrix_text('A', lin.A, lin.states, lin.states))
    print(_matrix_text('B', lin.B, lin.states, lin.inputs))
    print(_matrix_text('C', lin.C, lin.outputs, lin.states))
    print(_matrix_text('D', lin.D, lin.outputs, lin.inputs))
    poles = ', '.join(f'{p.real:.3f}{p.imag:+.3f}j' for p in lin.poles)
    print(f'poles (1/s): {poles}')
    print(
        f'controllability rank {ranks["controllability"]} / {ranks["states"]}, '
        f'observability rank {ranks["observability"]} / {ranks["states"]} '
        '(judged on a balanced, scaled model)'
    )
    return 0


def _simulate(args) -> int:
    from ..physics.equilibria import rest_state
    from ..physics.model import STATE_NAMES
    from ..physics.simulation import CoilDynamics, SensorEffects, Simulator

    model = _model(args)
    n_s = model.n_inputs
    currents = np.zeros(n_s) if args.currents is None else np.array(args.currents, dtype=float)
    if currents.shape != (n_s,):
        raise UsageError(
            f'--currents: expected {n_s} values (x+ x- y+ y-), got {len(args.currents)}'
        )
    from .progress import progress_bar, stage

    with stage(f'finding the equilibrium ({args.model} field model)', args.quiet):
        try:
            x0 = rest_state(model)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    for name, value in args.perturb.items():
        x0[STATE_NAMES.index(name)] += value
    coil = CoilDynamics.from_parameters(model.params) if args.coil else None
    sim = Simulator(
        model,
        sample_rate=args.rate,
        coil=coil,
        sensor=SensorEffects(noise_rms=args.noise),
        seed=args.seed,
        check_crash=not args.no_crash_check,
    )
    n = max(1, int(round(args.duration * args.rate)))
    inputs = np.tile(currents, (n, 1))
    sim.run(inputs[:1], x0=x0)  # compile / load the kernels outside the timing
    start = time.perf_counter()
    with progress_bar(100, f'simulating ({args.model} field model)', '%', args.quiet) as bar:

        def advance(done: int, total: int) -> None:
            bar.update(int(100 * done / total) - bar.n)

        result = sim.run(inputs, x0=x0, progress=advance)
    wall = time.perf_counter() - start
    simulated = result.t[-1]
    summary = {
        'params': model.params.name,
        'model': args.model,
        'samples': int(result.u.shape[0]),
        'sample_rate': args.rate,
        'simulated_time': float(simulated),
        'status': result.status,
        'reason': result.reason,
        'crash_time': result.crash_time,
        'crash_state': None if result.crash_state is None else result.crash_state.tolist(),
        'initial_state': x0.tolist(),
        'final_state': result.x[-1].tolist(),
        'z_range': [float(result.x[:, 2].min()), float(result.x[:, 2].max())],
        'wall_time': wall,
    }
    if args.csv:
        header = ['t', *STATE_NAMES, *(f'y{k}' for k in range(result.y.shape[1]))]
        np.savetxt(
            args.csv,
            np.column_stack([result.t, result.x, result.y]),
            delimiter=',',
            header=','.join(header),
            comments='',
        )
    if args.plot:
        _plot(result, args.plot, model.params.name)
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(
        f'{model.params.name}: {args.model} model, {summary["samples"]} samples at '
        f'{args.rate:g} Hz ({simulated:.4f} s simulated in {wall:.3f} s)'
    )
    print(f'start: {_state_text(x0)}')
    print(f'end:   {_state_text(result.x[-1])}')
    print(f'z between {summary["z_range"][0] * 1e3:.4f} and {summary["z_range"][1] * 1e3:.4f} mm')
    if result.crashed:
        print(
            f'status: crashed at t = {result.crash_time:.4f} s ({result.reason}); state '
            f'there: {_state_text(result.crash_state)}'
        )
    else:
        print('status: ok')
    for path in filter(None, (args.plot, args.csv)):
        print(f'wrote {path}')
    return 0


def _state_text(x: np.ndarray) -> str:
    return (
        f'x={x[0] * 1e3:.4f} y={x[1] * 1e3:.4f} z={x[2] * 1e3:.4f} mm, '
        f'alpha={x[3]:.4g} beta={x[4]:.4g} gamma={x[5]:.4g} rad'
    )


def simulation_figure(result, title: str):
    """Figure of a simulation: position (mm), angles (rad) and the sensors' Bz (mT) over time.

    Parameters
    ----------
    result : maglev_ros.physics.SimulationResult
        The simulation.
    title : str
        The parameter set's name, for the title.

    Returns
    -------
    matplotlib.figure.Figure
        Three axes sharing the time axis (s); close it when done.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    t = result.t
    for k, name in enumerate('xyz'):
        axes[0].plot(t, result.x[:, k] * 1e3, label=name)
    axes[0].set_ylabel('position, mm')
    for k, name in zip((3, 4, 5), ('alpha', 'beta', 'gamma'), strict=True):
        axes[1].plot(t, result.x[:, k], label=name)
    axes[1].set_ylabel('angle, rad')
    for k in range(result.y.shape[1] // 3):
        axes[2].plot(t, result.y[:, 3 * k + 2] * 1e3, label=f'Bz_{k}')
    axes[2].set_ylabel('field, mT')
    axes[2].set_xlabel('time, s')
    for ax in axes:
        ax.grid(True)
        ax.legend(loc='best', fontsize='small')
    status = 'ok' if not result.crashed else f'crashed at {result.crash_time:.4f} s'
    fig.suptitle(f'{title}: simulation ({status})')
    fig.tight_layout()
    return fig


def _plot(result, path: str, title: str) -> None:
    import matplotlib.pyplot as plt

    fig = simulation_figure(result, title)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _run(args: argparse.Namespace) -> int:
    with np.errstate(all='ignore'):
        return {'equilibria': _equilibria, 'linearize': _linearize, 'simulate': _simulate}[
            args.command
        ](args)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``maglev-model``; return the exit status (2 on bad input).

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.
    """
    return run_command(PROG, build_parser(), _run, argv)


if __name__ == '__main__':
    sys.exit(main())
