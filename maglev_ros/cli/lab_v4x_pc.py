"""``maglev-lab --firmware v4x_pc``: the closed-loop session on a V4x PC-control board.

With ``--board PATH`` (a board flashed with the PC-control firmware, docs/boards.md)
or ``--virtual-board`` (``maglev-virtual-board --firmware v4x_pc``, physics plant,
sensor noise 0.1 mT, the board's processing on), and ``--magnet free``: the loop of
:func:`maglev_ros.loop.v4x_pc_setup.run_v4x_pc_loop` (one ``03 01 02`` round
trip per sample at ``--control-rate``, default 1000 Hz; the KF with the board's
measurement model; the LQR on the pairs) holds the magnet for ``--samples``
samples (or ``--duration`` s; default 25 s), after ``--settle`` s of levitation
without excitation (default 0: the record starts at the start pose, from which
``maglev-calibrate`` separates the magnet's mass and polarisation; after a 1 s settle
it did not), with the excitation (``--excitation``,
``--amplitude``, default 0.3 A, ``--band``, default 0-0.05 of Nyquist) on the pairs
from the first sample, writes ``bag/`` and runs the identification with the physics
check through the board's processing
(:func:`maglev_ros.sysid.board_check.check_board_bag`): ``models.json``.

With ``--virtual-board`` the board runs in its own process and session (under
Linux's autogroup scheduling it then has its own share of the CPU, as a board
has its own processor) and writes the magnet's true pose to ``truth.csv``: the
largest true |x|, |y| over the run is printed and kept in ``models.json``.
``--board-params`` gives the virtual board another physics set than the one
the loop believes (``--params``): a bag for ``maglev-calibrate --measurement
board`` to recover.

Exit status 0 when all samples were run and identified, 1 when the loop stopped
early, the virtual board's magnet crashed or the record could not be identified
(e.g. gaps: periods the host started late; the reason is printed, the bag keeps
what was recorded), 2 on bad input.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from maglev_ros.cli.usage import UsageError

__all__ = ['check_v4x_pc', 'run_v4x_pc_session']

PROG = 'maglev-lab'
V4X_PC_RATE = 1000.0  # Hz, samples (and commands) per second by default
V4X_PC_SECONDS = 25.0  # s of samples by default (--duration, --samples)
V4X_PC_AMPLITUDE = 0.3  # A per pair: the loop rejects most of it; the hold is noise-bound
V4X_PC_BAND = (0.0, 0.05)  # of Nyquist: 0-25 Hz at 1 kHz, where the field sees the motion
PLACE_MARGIN = 1.0  # s the virtual board's magnet comes after the feedthrough measurement


def check_v4x_pc(args: argparse.Namespace) -> None:
    """Refuse what the V4x PC-control session cannot run (one line each).

    Parameters
    ----------
    args : argparse.Namespace
        maglev-lab's parsed arguments.

    Raises
    ------
    UsageError
        No board, the magnet not free, or a sample rate other than the loop's.
    """
    if not (args.board or args.virtual_board):
        raise UsageError('--firmware v4x_pc needs --board PATH or --virtual-board')
    if args.magnet not in (None, 'free'):
        raise UsageError(
            f'--firmware v4x_pc runs the closed loop: --magnet free (got {args.magnet})'
        )
    if args.samples is not None and args.samples < 2:
        raise UsageError(f'--samples must be >= 2, got {args.samples}')
    if not 0 <= getattr(args, 'realtime_priority', 0) <= 99:
        raise UsageError(f'--realtime-priority must be 0 to 99, got {args.realtime_priority}')
    if getattr(args, 'board_params', None) is not None and not args.virtual_board:
        raise UsageError("--board-params is the virtual board's set: add --virtual-board")


def run_v4x_pc_session(args: argparse.Namespace, out: Path, bag: Path) -> int:
    """Run the session (module docstring); return the exit status.

    Parameters
    ----------
    args : argparse.Namespace
        maglev-lab's parsed arguments (checked by :func:`check_v4x_pc`).
    out, bag : Path
        The output directory and its bag (new).
    """
    from maglev_ros.cli.lab_board import stop_child
    from maglev_ros.control.excitation import CommandExcitation
    from maglev_ros.hardware.v4x_pc_link import V4xPcLink
    from maglev_ros.hardware.v4x_pc_poller import REPLY_TIMEOUT_S
    from maglev_ros.loop.sample_log import write_sample_bag
    from maglev_ros.loop.v4x_pc_setup import V4xPcLoopSettings, run_v4x_pc_loop
    from maglev_ros.sysid.board_check import check_board_bag

    rate = args.control_rate or V4X_PC_RATE
    seconds = V4X_PC_SECONDS if args.duration is None else args.duration
    samples = args.samples or max(2, int(round(seconds * rate)))
    board_params = getattr(args, 'board_params', None) or args.params
    amplitude = V4X_PC_AMPLITUDE if args.amplitude is None else args.amplitude
    band = V4X_PC_BAND if args.band is None else tuple(args.band)
    try:
        settings = V4xPcLoopSettings(
            params=args.params, sample_rate=rate, realtime_priority=args.realtime_priority
        )
        excitation = CommandExcitation(
            args.excitation, amplitude, band, 'pairs', seed=args.seed, length=samples
        )
    except ValueError as err:
        raise UsageError(str(err)) from None
    where = args.board or f'a virtual V4x PC-control board ({board_params}, magnet free)'
    print(
        f'{PROG}: {samples} samples at {rate:g} Hz on {where}, {args.excitation} '
        f'{amplitude:g} A on the pairs, seed {args.seed}',
        flush=True,
    )
    child = None
    port = args.board or str(out / 'ttyMAGGY')
    truth = out / 'truth.csv' if args.virtual_board else None

    def start() -> None:  # after the loop is built: a free magnet falls from set-up's end
        nonlocal child
        if args.virtual_board:
            child = _start_board(args, port, board_params, truth)

    link = V4xPcLink(port, timeout=REPLY_TIMEOUT_S, open_timeout=30.0)
    t0 = time.monotonic()
    try:
        settle = round((args.settle or 0.0) * rate)
        run = run_v4x_pc_loop(
            settings, link, samples, excitation, ready=start, settle=settle,
            notice=lambda text: print(f'{PROG}: {text}', flush=True),
        )  # fmt: skip
    except (OSError, ValueError) as err:
        raise UsageError(str(err)) from None
    finally:
        if child is not None:
            stop_child(child)
    wall = time.monotonic() - t0
    print(
        f'{run.samples} samples in {wall:.1f} s: rate {run.rate_reached:.1f} Hz (set {rate:g}), '
        f'{run.late} late periods; board round trips {run.round_trip_rate:.0f} /s (median)'
        + (f'; stopped: {run.reason}' if run.reason else '')
    )
    if run.priority_note:
        print(f'{PROG}: {run.priority_note}')
    extra = {}
    if run.feedthrough is not None:
        print(f'the magnet came {run.magnet_wait:.2f} s after the feedthrough measurement')
        extra.update(run.feedthrough.metadata())
    write_sample_bag(
        bag,
        run.log,
        (settings.sensor,),
        {
            'magnet': 'free',
            'params': board_params,
            'believed_params': args.params,
            'firmware': 'v4x_pc',
            'measurement': 'board',
            'sample_rate': rate,
            'seed': args.seed,
            **extra,
        },
    )
    print(f'wrote {bag}')
    true_max, crashed, settling = None, False, None
    if truth is not None and truth.exists():
        true_max, crashed = _true_excursion(truth, run.started, run.ended)
        settling, _ = _true_excursion(truth, run.settled_from, run.started)
        if true_max is not None:
            print(
                f"magnet (the virtual board's truth, {truth}) over the record: max |x| "
                f'{1e3 * true_max[0]:.3f} mm, max |y| {1e3 * true_max[1]:.3f} mm'
                + (
                    f' (settling: {1e3 * settling[0]:.3f}, {1e3 * settling[1]:.3f} mm)'
                    if settling
                    else ''
                )
                + ('; it crashed' if crashed else '')
            )
    est = run.log.arrays()['estimates']
    summary = {
        'samples': run.samples,
        'rate_hz': run.rate_reached,
        'late_periods': run.late,
        'round_trip_rate_hz': run.round_trip_rate,
        'stopped': run.reason,
        'estimated_max_abs_xy_m': np.nanmax(np.abs(est[:, :2]), axis=0).tolist()
        if len(est)
        else None,
        'true_max_abs_xy_m': true_max,
        'true_max_abs_xy_settling_m': settling if truth is not None else None,
        'crashed': crashed,
        'board_params': board_params,
        'board_feedthrough_T_per_A': None
        if run.feedthrough is None
        else np.asarray(run.feedthrough.response).tolist(),
        'models': [],
    }
    if run.samples == samples:
        from maglev_ros.bags import BagError

        try:
            data, results, checks = check_board_bag(bag, board_params, settings.sensor)
        except (BagError, ValueError) as err:
            summary['identification'] = f'not run: {err}'
            print(f'identification not run: {err}')
            results, checks = (), {}
        if results:
            print(
                f'identified on the record decimated to {1 / data.Ts:.0f} Hz '
                '(the seed orders and a high-order ARX, on the band the data carry)'
            )
            summary['identification_rate_hz'] = 1 / data.Ts
        print(f'{"model":<28} {"fit val. %":>10}  {"physics check (1-10 Hz)":<24} status')
        for item in results:
            for row in item.result.rows:
                check = checks.get((item.group.name, row.label))
                text = check.brief() if hasattr(check, 'max_db') else ''
                fit = float(np.mean(row.fit_validation))
                print(
                    f'{item.group.name + " " + row.label:<28} {fit:10.1f}  {text:<24} {row.status}'
                )
                summary['models'].append(
                    {
                        'group': item.group.name,
                        'model': row.label,
                        'status': row.status,
                        'fit_validation': fit if np.isfinite(fit) else None,
                        'physics_max_db': getattr(check, 'max_db', None),
                        'physics_max_deg': getattr(check, 'max_deg', None),
                        'physics_notches_hz': list(getattr(check, 'notches', ())),
                        'physics_left_out_hz': [list(b) for b in getattr(check, 'uncertain', ())],
                        'unstable_physics_per_s': getattr(check, 'unstable_reference', None),
                        'unstable_model_per_s': getattr(check, 'unstable_model', None),
                    }
                )
        _explain_checks(checks)
    (out / 'models.json').write_text(json.dumps(summary, indent=1))
    print(f'wrote {out / "models.json"}')
    return 0 if run.samples == samples and 'identification' not in summary and not crashed else 1


def _explain_checks(checks: dict) -> None:
    """Print what the physics check left out, and what a missed unstable pole means."""
    from maglev_ros.sysid.physics_check import RESONANCE_WIDTH

    done = [c for c in checks.values() if hasattr(c, 'max_db')]
    notches = sorted({f for c in done for f in c.notches})
    left_out = sorted({b for c in done for b in c.uncertain})
    if notches or left_out:
        print(
            'physics check without '
            + ', '.join(
                [f'+-{RESONANCE_WIDTH:g} Hz around the notch at {f:.2f} Hz' for f in notches]
                + [f'{lo:.2f}-{hi:.2f} Hz' for lo, hi in left_out]
            )
            + ": where the feedthrough a pair leaves cancels the magnet's response, the "
            'reference is less than half of either part, and any error of a part at least '
            'doubles in the ratio'
        )
    missed = [c for c in done if c.misses_instability]
    if missed:
        rate = missed[0].unstable_reference[0]
        print(
            f'no unstable pole: the model has a stable pole where the magnet is unstable '
            f'({rate:.0f} 1/s, time constant {1e3 / rate:.0f} ms): the same gain, the phase '
            "up to 180 deg off: an ARX too short for the sensor noise's predictor prefers the "
            "pole's stable mirror, and an IV on a weak excitation can land there "
            '(docs/identify.md); read ARMAX or the high-order ARX'
        )


def _true_excursion(truth: Path, started: float, ended: float):
    """Largest true |x|, |y| (m) over the loop's run, and whether the magnet crashed.

    Returns ``(None, False)`` when the truth file has no row in the run.
    """
    rows = np.loadtxt(truth, delimiter=',', skiprows=1, ndmin=2)
    during = rows[(rows[:, 7] >= started) & (rows[:, 7] <= ended)] if rows.size else rows
    if not len(during):
        return None, False
    return np.abs(during[:, 1:3]).max(axis=0).tolist(), bool(during[:, 6].any())


def _start_board(args: argparse.Namespace, link: str, params: str, truth: Path):
    """Start ``maglev-virtual-board --firmware v4x_pc --magnet free`` on ``link``."""
    import subprocess
    import sys

    from maglev_ros.hardware.v4x_pc_feedthrough import measurement_time

    # the magnet goes in place once the host has measured the board without it (+ margin)
    place = measurement_time(1.0 / (args.control_rate or V4X_PC_RATE)) + PLACE_MARGIN
    cmd = [
        sys.executable, '-m', 'maglev_ros.cli.virtual_board', '--firmware', 'v4x_pc',
        '--magnet', 'free', '--params', params, '--link', link, '--seed', str(args.seed),
        '--truth', str(truth), '--exit-with-parent', '--place-after', f'{place:g}',
        '--realtime-priority', str(args.realtime_priority),
    ]  # fmt: skip
    # its own session: under Linux's autogroup scheduling the board's emulator then gets its
    # own share of the CPU, as a board has its own processor, instead of half the loop's
    child = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    if not child.stdout.readline().strip():
        child.wait(timeout=60)
        raise UsageError(f'the virtual board did not start: {child.stderr.read().strip()}')
    return child
