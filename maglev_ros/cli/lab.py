"""``maglev-lab``: the lab session as one command (pip-only friendly).

Closed loop (the magnet ``free``, the default; :mod:`maglev_ros.cli.closed_loop_lab`):
the lab session (:func:`maglev_ros.loop.run_session`) runs the control loop
(simulator in lockstep, estimator, controller with its excitation) with the
online identifier and the bag writer as its observers; the magnet levitates
and settles, exactly ``--samples`` samples are recorded and the seed's models
(x, y and MIMO: ARX, IV on the excitation, ARMAX) are identified, checked
against the physics and compared with the online identifier::

    maglev-lab --out lab/

Open loop (``--magnet fixed`` or ``absent``): the same lab session on the
simulator (lockstep) with the open loop as its controller (the excitation
node's signal, one command a sample) and the bag writer as its observer, for a
given simulated duration; then converts the bag into a data set
(:func:`maglev_ros.bags.read_bag`: command inputs by log time, exact alignment),
identifies one ARX model per field component against the excitation inputs,
prints the fit on estimation and validation data and writes the plots::

    maglev-lab --duration 5 --params maggy_v2 --magnet fixed --excitation prbs --out lab/

Against a board (real time: the board sets the pace, ``--duration`` is seconds of
board samples): ``--board PATH`` runs the lab session on a serial device
(:class:`~maglev_ros.loop.BoardPlant`) instead of the simulator;
``--virtual-board`` starts ``maglev-virtual-board --plant physics``
(``--params``, ``--magnet``) in a child process and uses it. The excitation is
then one command each ``--command-rate`` period of board samples, the inputs are
the currents the board reports as applied (``maglev/currents:effort[coil]``,
header stamps) and the default ARX delay is 0 (a record's field and PWM are
simultaneous)::

    maglev-lab --virtual-board --magnet fixed --duration 3 --amplitude 0.2 --out lab/

The closed loop against a board (``--board PATH --magnet free``, or
``--virtual-board --magnet free``: its physics plant with the magnet free,
``--noise``, ``--quantization``, ``--delay``, ``--seed``):
the same session with a :class:`~maglev_ros.loop.BoardPlant` in place of the
simulator, in this process; exactly ``--samples`` board records are recorded
after the settling::

    maglev-lab --virtual-board --magnet free --out lab_board/

Outputs in ``--out``: ``bag/`` (rosbag2, MCAP), ``models.json`` (fits and
coefficients), ``compare_<output>.png`` (validation data vs model). In lockstep
exactly ``--samples`` samples are recorded (the excitation stops after that many
commands). Exit status 0, 1 when a model is not usable (failed, or a residual
test failed: its row says why; everything else is written), 2 on bad input
(one line on stderr), 130 when interrupted (the bag is finalised).
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import sys
import time
from pathlib import Path

import numpy as np

from maglev_ros.bags.reader import is_bag_directory
from maglev_ros.cli.lab_board import (
    BOARD_TS,
    board_sensors,
    on_board,
    start_virtual_board,
    stop_child,
)
from maglev_ros.cli.progress import progress_bar
from maglev_ros.cli.usage import (
    Parser,
    UsageError,
    limit_blas_threads,
    non_negative_float,
    positive_float,
    run_command,
)
from maglev_ros.excitation import PATTERNS, SIGNALS, pattern_matrix
from maglev_ros.stop_signals import StopSignals
from maglev_ros.topics import (
    AXES,
    CURRENTS_TOPIC,
    command_channel,
    current_channel,
    field_channel,
)

__all__ = [
    'applied_channels',
    'build_parser',
    'identify',
    'input_channels',
    'load_data',
    'main',
    'on_board',
    'run_board_experiment',
    'run_experiment',
    'start_virtual_board',
]

PROG = 'maglev-lab'
WAIT_S = 60.0  # s, longest wait for the graph (discovery) and for the recorder to drain
BOARD_READ_INTERVAL = 0.002  # s between port reads in board runs (open loop: latency is free)
BOARD_CONTROL_RATE = 500.0  # Hz, the closed loop's default on a board (docs/benchmarks.md)
DEFAULT_SAMPLES = 25000  # the lab's record: 5 s at 5 kHz, split 12500 / 12500


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-lab``."""
    p = Parser(
        prog=PROG,
        description='Simulate, excite, record and identify: the Maggy lab session in one command.',
    )
    length = p.add_mutually_exclusive_group()
    length.add_argument(
        '--samples',
        type=int,
        default=None,
        help='samples to record (simulator: exactly this many; default 25000 at 5 kHz, '
        "the lab's 5 s record)",
    )
    length.add_argument(
        '--duration',
        type=positive_float,
        default=None,
        help='seconds to record instead: simulated (--samples = duration x --sample-rate), '
        "or of the board's samples against a board (default 5)",
    )
    p.add_argument(
        '--params', default='maggy_v2', help='parameter set (maggy_v2, maggy_v4, or a YAML path)'
    )
    p.add_argument(
        '--magnet',
        choices=('free', 'fixed', 'absent'),
        default=None,
        help='free (default): the closed-loop session (estimator, controller with its '
        'excitation, identifier); fixed or absent: the open-loop session (excitation '
        'node); with --board or --virtual-board the default is fixed',
    )
    p.add_argument('--field-model', choices=('fast', 'accurate', 'filament'), default='fast')
    p.add_argument('--sample-rate', type=positive_float, default=5000.0, help='Hz')
    p.add_argument('--no-coil', action='store_true', help='no coil L/R dynamics')
    p.add_argument('--delay', type=int, default=1, help='sensor delay in samples (default 1)')
    p.add_argument(
        '--noise',
        type=non_negative_float,
        default=None,
        help='sensor noise, T rms (default: 1e-4 closed loop, 0 open loop)',
    )
    p.add_argument(
        '--quantization',
        type=non_negative_float,
        default=0.098e-3,
        help='closed loop: sensor resolution, T per LSB (default 0.098e-3)',
    )
    p.add_argument('--seed', type=int, default=0, help='seed of noise and excitation')
    p.add_argument(
        '--sensors',
        type=int,
        nargs='+',
        default=[0],
        help='sensors to record and identify (default 0)',
    )
    p.add_argument('--excitation', choices=SIGNALS, default='prbs', help='input signal')
    p.add_argument(
        '--amplitude',
        type=non_negative_float,
        default=None,
        help='A (default: 0.1 added to the closed loop, 0.5 open loop)',
    )
    p.add_argument(
        '--band',
        type=float,
        nargs=2,
        default=None,
        metavar=('LOW', 'HIGH'),
        help='band as fractions of Nyquist (default: 0 0.2 closed loop, 0 1 open loop)',
    )
    p.add_argument(
        '--pattern',
        choices=PATTERNS,
        default='pairs',
        help='coil pattern (default pairs: +u on x+, -u on x-, same for y)',
    )
    p.add_argument(
        '--length',
        type=int,
        default=None,
        help='samples per excitation period (default: --samples closed loop, 8191 open loop)',
    )
    closed = p.add_argument_group('closed loop (--magnet free)')
    closed.add_argument(
        '--settle',
        type=non_negative_float,
        default=None,
        help='s of levitation before the recording (default 1; --firmware v4x_pc: 0, the '
        'record starts at the start pose, which maglev-calibrate needs)',
    )
    closed.add_argument(
        '--filter', choices=('kf', 'ekf', 'ukf'), default='kf', help='estimator (default kf)'
    )
    closed.add_argument(
        '--instruments',
        choices=('excitation', 'inputs'),
        default='excitation',
        help="IV instruments: the controller's excitation (default; unbiased in closed "
        'loop) or the inputs (iv4, biased in closed loop)',
    )
    closed.add_argument(
        '--check-band',
        type=positive_float,
        nargs=2,
        default=[10.0, 300.0],
        metavar=('LOW', 'HIGH'),
        help='physics check band, Hz (default 10 300)',
    )
    closed.add_argument(
        '--realtime',
        action='store_true',
        help='run on the wall clock: the loop composed in this process, samples, estimates '
        "and commands handed over in the simulator's thread, control at --control-rate "
        '(default: lockstep, exact and deterministic)',
    )
    closed.add_argument(
        '--control-rate',
        type=positive_float,
        default=None,
        help='--realtime and boards: estimates and commands per second, Hz (divides '
        '--sample-rate; default 1000, on a board 500)',
    )
    p.add_argument('--na', type=int, default=2, help='ARX order of A (default 2)')
    p.add_argument('--nb', type=int, default=2, help='ARX order of B per input (default 2)')
    p.add_argument(
        '--nk', type=int, default=None, help='ARX input delay (default 1; 0 against a board)'
    )
    p.add_argument(
        '--split', type=float, default=0.5, help='fraction of samples for estimation (default 0.5)'
    )
    p.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap')
    p.add_argument('--out', default=None, help='output directory (default lab_<date>_<time>)')
    p.add_argument(
        '--overwrite',
        action='store_true',
        help="replace a previous session's results in --out (its bag/ is removed)",
    )
    p.add_argument('--no-plots', action='store_true', help='write no plots')
    p.add_argument('--quiet', action='store_true', help='no progress display')
    p.add_argument(
        '--firmware',
        choices=('v2x', 'v4x_pc'),
        default='v2x',
        help='board firmware: v2x (default) or v4x_pc (the V4x PC-control firmware: the '
        'closed loop at 1000 Hz on its processed field, maglev_ros.cli.lab_v4x_pc)',
    )
    board = p.add_mutually_exclusive_group()
    board.add_argument(
        '--board',
        metavar='PATH',
        default=None,
        help='run the driver on this serial device instead of the simulator (with --magnet '
        'free: the closed-loop session on the board)',
    )
    board.add_argument(
        '--virtual-board',
        action='store_true',
        help='start a virtual board (physics plant, --params, --magnet) in a '
        'child process and run the driver on it',
    )
    p.add_argument(
        '--board-params',
        metavar='PARAMS',
        default=None,
        help="--firmware v4x_pc --virtual-board: the virtual board's physics set (preset or "
        'YAML; default --params): a magnet that is not the one the loop believes (--params)',
    )
    p.add_argument(
        '--realtime-priority',
        type=int,
        default=0,
        metavar='N',
        help='--firmware v4x_pc: SCHED_FIFO priority 1-99 of the loop (and of a virtual '
        "board's emulator), as ros2_control's node runs its loop; needs the right to "
        '(an rtprio limit, CAP_SYS_NICE); default 0: the normal policy',
    )
    p.add_argument(
        '--board-sensors',
        type=int,
        default=None,
        help='sensors per board record (default: --params for a virtual board, '
        'else max(--sensors) + 1)',
    )
    p.add_argument(
        '--command-rate',
        type=positive_float,
        default=1000.0,
        help="board: excitation commands per second of the board's samples, Hz (default 1000)",
    )
    return p


def _input_coils(pattern: str) -> list[tuple[str, int]]:
    """(label, coil) of each pattern signal: the first coil it drives (the ``+u`` coil)."""
    matrix = pattern_matrix(pattern)
    names = {0: 'x', 2: 'y', 1: 'xm', 3: 'ym'}
    coils = []
    for j in range(matrix.shape[1]):
        coil = int(np.flatnonzero(matrix[:, j])[0])
        coils.append((names[coil] if matrix.shape[1] > 1 else pattern, coil))
    return coils


def input_channels(pattern: str) -> list[str]:
    """Bag channel specs of the excitation inputs: one per pattern signal.

    Each signal is read from the first coil it drives, as commanded (the
    ``+u`` coil of an antisymmetric pair), e.g. ``u_x=maglev/currents/command:data[0]``.

    Parameters
    ----------
    pattern : str
        Coil pattern (:data:`maglev_ros.excitation.PATTERNS`).

    Returns
    -------
    list of str
    """
    return [f'u_{label}={command_channel(coil)}' for label, coil in _input_coils(pattern)]


def applied_channels(pattern: str) -> list[str]:
    """Bag channel specs of the currents applied to the excitation's coils (board runs).

    As :func:`input_channels`, read from the driver's ``maglev/currents`` (header
    stamps of the board's records), e.g. ``u_x=maglev/currents:effort[0]``.

    Parameters
    ----------
    pattern : str
        Coil pattern (:data:`maglev_ros.excitation.PATTERNS`).

    Returns
    -------
    list of str
    """
    return [f'u_{label}={current_channel(coil)}' for label, coil in _input_coils(pattern)]


def output_channels(sensors) -> list[str]:
    """Bag channel specs of the field components of ``sensors``.

    Parameters
    ----------
    sensors : sequence of int
        Sensor indices.

    Returns
    -------
    list of str
        ``B<axis>_<k>=<field channel>`` for each sensor and axis.
    """
    return [f'B{a}_{k}={field_channel(k, a)}' for k in sensors for a in AXES]


def load_data(bag: Path, sensors, pattern: str, board: bool = False):
    """Read the recorded experiment into an identification data set.

    Parameters
    ----------
    bag : Path
        The bag directory.
    sensors : sequence of int
        Sensors whose fields are the outputs.
    pattern : str
        Excitation pattern (chooses the inputs).
    board : bool
        A board run: the inputs are the applied currents, ``Ts`` is the
        board's 200 us, and gaps (records lost between board and bag: resyncs
        or messages the recorder missed) are filled and reported instead of
        refused. The driver stamps the fields and currents of one record alike
        (uniform, slewed board clock), so the converter takes every record
        unchanged, as it takes a lockstep simulator run.

    Returns
    -------
    maglev_ros.bags.BagDataset
        Data (outputs in T, inputs in A) and the bag's metadata.
    """
    from maglev_ros.bags import read_bag

    if board:
        return read_bag(
            bag, output_channels(sensors), applied_channels(pattern), Ts=BOARD_TS, allow_gaps=True
        )
    return read_bag(bag, output_channels(sensors), input_channels(pattern))


def identify(data, na: int, nb: int, nk: int, split: float, quiet: bool = True):
    """Estimate one ARX model per output (all inputs) with :mod:`maglev_ros.sysid.workflow`.

    Parameters
    ----------
    data : IdData
        The experiment (raw; detrended here).
    na, nb, nk : int
        ARX orders (``nb``, ``nk`` for every input).
    split : float
        Fraction of samples for estimation.
    quiet : bool
        No progress display.

    Returns
    -------
    maglev_ros.sysid.workflow.Identification
        One row per output: ``ok``, ``reduced``, ``unstable``, ``failed``, or
        ``no response`` for an output that does not respond to the inputs
        (constant after detrending, e.g. by symmetry); fits in percent.
    """
    from maglev_ros.sysid.workflow import ModelSpec, identify_outputs

    est, val = data.detrend().split(split)
    spec = ModelSpec('arx', {'na': na, 'nb': nb, 'nk': nk})
    with progress_bar(None, 'identifying', 'outputs', quiet):
        return identify_outputs(est, val, spec, ic='estimate')


def closed_loop(args: argparse.Namespace) -> bool:
    """Whether the session is the closed loop (the magnet free, the default).

    Parameters
    ----------
    args : argparse.Namespace
        maglev-lab's parsed arguments.
    """
    return getattr(args, 'magnet', 'free') == 'free'


def _defaults(args: argparse.Namespace) -> None:
    """Fill the settings whose defaults depend on the session (closed or open loop)."""
    closed = closed_loop(args)
    if args.noise is None:
        args.noise = 1e-4 if closed else 0.0
    if args.amplitude is None:
        args.amplitude = 0.1 if closed else 0.5
    if args.band is None:
        args.band = [0.0, 0.2] if closed else [0.0, 1.0]
    if args.length is None:
        args.length = args.samples if closed else 8191


def _check_closed_loop(args: argparse.Namespace) -> None:
    """Refuse what the closed-loop session does not run, saying what does."""
    if on_board(args):
        if args.sample_rate != 1.0 / BOARD_TS:
            raise UsageError(
                f"--sample-rate must be the board's {1.0 / BOARD_TS:g} Hz with --board or "
                f'--virtual-board, got {args.sample_rate:g}'
            )
        if args.delay < 1:
            raise UsageError(
                f'--delay must be >= 1 on a board (a record reads its field at the end of the '
                f'sample its PWM drives), got {args.delay}'
            )
        args.realtime = True  # the board sets the pace
        if args.virtual_board:
            args.no_coil = True  # the virtual board's plant drives ideal coils
    if args.control_rate is None:  # a board's loop also waits for its link: more slack
        args.control_rate = BOARD_CONTROL_RATE if on_board(args) else 1000.0
    ratio = args.sample_rate / args.control_rate
    if args.realtime and (ratio < 1 or abs(ratio - round(ratio)) > 1e-9):
        raise UsageError(
            f'--control-rate must divide --sample-rate {args.sample_rate:g} Hz into whole '
            f'samples, got {args.control_rate:g} Hz'
        )
    if args.excitation == 'none' or args.amplitude == 0:
        raise UsageError('--amplitude must be > 0: the closed-loop IV needs the excitation')
    if args.sensors != [0]:
        raise UsageError(
            f'--sensors: the closed-loop session records and identifies sensor 0 (the '
            f"seed's models), got {args.sensors}"
        )
    if args.check_band[0] >= args.check_band[1]:
        raise UsageError(f'--check-band must be LOW HIGH with LOW < HIGH, got {args.check_band}')
    if args.check_band[1] > args.sample_rate / 2:
        raise UsageError(
            f'--check-band: HIGH must be at most Nyquist ({args.sample_rate / 2:g} Hz), '
            f'got {args.check_band[1]:g}'
        )


def _check(args: argparse.Namespace) -> None:
    if args.settle is None:
        args.settle = 1.0
    elif args.settle <= 0:
        raise UsageError(f'--settle must be > 0 s for the simulated session, got {args.settle:g}')
    if args.magnet is None:  # the closed loop, except on a board (the open-loop session)
        args.magnet = 'fixed' if on_board(args) else 'free'
    if args.samples is not None and args.samples < 2:
        raise UsageError(f'--samples must be >= 2, got {args.samples}')
    if args.duration is None:
        args.duration = (args.samples or DEFAULT_SAMPLES) / args.sample_rate
    if args.samples is None:
        args.samples = max(2, int(round(args.duration * args.sample_rate)))
    if not 0.0 < args.split < 1.0:
        raise UsageError(f'--split must be in (0, 1), got {args.split}')
    _check_params(args.params)
    for name in ('na', 'nb'):
        if getattr(args, name) < 1:
            raise UsageError(f'--{name} must be >= 1, got {getattr(args, name)}')
    if args.nk is None:
        args.nk = 0 if on_board(args) else 1
    if args.board_sensors is not None and args.board_sensors < 1:
        raise UsageError(f'--board-sensors must be >= 1, got {args.board_sensors}')
    if args.nk < 0 or args.delay < 0:
        raise UsageError('--nk and --delay must be >= 0')
    _defaults(args)
    if not 0.0 <= args.band[0] < args.band[1] <= 1.0:
        raise UsageError(f'--band must be LOW HIGH with 0 <= LOW < HIGH <= 1, got {args.band}')
    if args.length < 1:
        raise UsageError(f'--length must be >= 1, got {args.length}')
    if closed_loop(args):
        _check_closed_loop(args)


def _check_params(params: str) -> None:
    """Refuse a parameter set that cannot be read, before anything is started or created."""
    from maglev_ros.physics import ParameterError, load_parameters

    try:
        load_parameters(params)
    except ParameterError as err:
        raise UsageError(f'--params {params!r}: {err}') from None


def overrides(**values) -> list:
    """Return ROS parameter overrides ``name=value`` for a node built in this process.

    Parameters
    ----------
    **values : object
        Parameter values by name.
    """
    from rclpy.parameter import Parameter

    return [Parameter(k, value=v) for k, v in values.items()]


def run_experiment(args: argparse.Namespace, bag: Path, stop=None) -> dict:
    """Record the simulated platform driven by the excitation: the open-loop lab session.

    The lab session (:func:`~maglev_ros.loop.run_session`, no settling) on a
    lockstep :class:`~maglev_ros.loop.SimulatedPlant` (the magnet ``fixed`` or
    ``absent``) with the :class:`~maglev_ros.loop.OpenLoop` controller: the
    excitation node's signal (one period, repeated) from the first sample on,
    one command a sample, exactly ``--samples`` samples recorded.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``maglev-lab`` arguments.
    bag : Path
        Bag directory to create.
    stop : maglev_ros.stop_signals.StopSignals, optional
        Ends the run when a stop signal arrives.

    Returns
    -------
    dict
        ``samples``, ``simulated_s``, ``wall_s``, ``timeouts``, ``crashed``,
        ``crash_reason``, ``stopped``.
    """
    from maglev_ros.loop import (
        BagRecorder,
        ControlLoop,
        OpenLoop,
        SessionPlan,
        SimulatedPlant,
        run_session,
    )
    from maglev_ros.nodes.excitation import build_config as excitation_config
    from maglev_ros.nodes.excitation import commands_of
    from maglev_ros.nodes.simulator import build_config as simulator_config
    from maglev_ros.physics.simulator_config import make_simulator

    settings = dict(
        params=args.params,
        field_model=args.field_model,
        magnet=args.magnet,
        sample_rate=args.sample_rate,
        coil_dynamics=not args.no_coil,
        sensor_delay=args.delay,
        sensor_noise=args.noise,
        seed=args.seed,
        mode='lockstep',
    )
    simulator = make_simulator(simulator_config(settings))
    excitation = dict(
        signal=args.excitation,
        amplitude=args.amplitude,
        band=list(args.band),
        pattern=args.pattern,
        seed=args.seed,
        length=args.length,
    )
    period = commands_of(excitation_config(excitation))
    # the command answering sample k is period row k (mod its length), applied at once
    loop = ControlLoop(
        SimulatedPlant(simulator), OpenLoop(), excitation=np.resize(period, (args.samples, 4))
    )
    metadata = {f'maglev_simulator.{k}': v for k, v in settings.items()}
    metadata['maglev_simulator.sensors'] = ' '.join(str(k) for k in args.sensors)
    metadata.update({f'maglev_excitation.{k}': str(v) for k, v in excitation.items()})
    recorder = BagRecorder(bag, args.sensors, args.storage, metadata, true_state=True, clock=True)
    try:
        with progress_bar(args.samples, 'simulating', 'samples', args.quiet) as bar:

            def progress(stage: str, done: int, total: int) -> None:
                if stage == 'recording':
                    bar.update(done - bar.n)

            plan = SessionPlan(args.samples, 0, settle_window=1)
            stopped = lambda: bool(stop and stop.requested)  # noqa: E731
            result = run_session(loop, plan, {'recorder': recorder}, progress, stopped)
    finally:
        recorder.close()
    return {
        'samples': recorder.counts[CURRENTS_TOPIC],
        'simulated_s': args.samples / args.sample_rate,
        'wall_s': result.wall_s,
        'timeouts': 0,
        'crashed': result.crashed,
        'crash_reason': result.reason,
        'stopped': result.stopped,
    }


def run_board_experiment(
    args: argparse.Namespace, bag: Path, port: str, n_sensors: int, stop=None
) -> dict:
    """Record the board (on ``port``) driven by the excitation: the open-loop lab session.

    The lab session (:func:`~maglev_ros.loop.run_session`) on a
    :class:`~maglev_ros.loop.BoardPlant` with the :class:`~maglev_ros.loop.OpenLoop`
    controller: one excitation command each ``--command-rate`` period of
    board samples, ``--duration`` s of board samples recorded from the
    first command on (the board sets the pace).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``maglev-lab`` arguments.
    bag : Path
        Bag directory to create.
    port : str
        Serial device of the board.
    n_sensors : int
        Sensors per board record.
    stop : maglev_ros.stop_signals.StopSignals, optional
        Ends the run when a stop signal arrives.

    Returns
    -------
    dict
        ``samples`` (in the bag), ``simulated_s`` (their board time),
        ``wall_s``, ``timeouts``, ``crashed``, ``crash_reason``, ``driver``
        (the board plant's counters), ``stopped``.
    """
    from maglev_ros.control.excitation import CommandExcitation, ExcitationSchedule
    from maglev_ros.loop import (
        BagRecorder,
        BoardPlant,
        ControlLoop,
        ObserverThread,
        OpenLoop,
        SessionPlan,
        run_session,
    )

    burst = max(1, int(round(1.0 / (BOARD_TS * args.command_rate))))
    samples = max(2, int(round(args.duration / BOARD_TS)))
    try:  # the excitation node's signal, one value a command
        signal_ = CommandExcitation(
            args.excitation, args.amplitude, tuple(args.band), args.pattern, args.seed,
            args.length,
        )  # fmt: skip
        periods = samples // burst + 2
        values = ExcitationSchedule(signal_, args.command_rate).sequence(periods)
    except ValueError as err:
        raise UsageError(f'--excitation {args.excitation}: {err}') from None
    # an open-loop recording: latency does not matter, so the plant reads the port
    # every 2 ms (two bursts per read), which roughly halves its CPU time
    plant = BoardPlant(
        port,
        n_sensors,
        burst=burst,
        command_timeout=1.0,
        confirm_records=True,
        read_interval=BOARD_READ_INTERVAL,
    )
    loop = ControlLoop(plant, OpenLoop())
    plan = SessionPlan(
        samples, 1, settle_window=1, position='estimate', excitation=values.repeat(burst, 0)
    )
    recorder = BagRecorder(
        bag, args.sensors, args.storage, plant.metadata(), true_state=False, clock=False
    )
    writer = ObserverThread(recorder, 10 * samples + 1000, 'maglev-lab-recorder')
    try:
        with progress_bar(samples, 'recording', 'samples', args.quiet) as bar:

            def progress(stage: str, done: int, total: int) -> None:
                if stage == 'recording':
                    bar.update(done - bar.n)

            plant.open()
            result = run_session(
                loop, plan, {'recorder': writer}, progress, lambda: bool(stop and stop.requested)
            )
    finally:
        writer.close(timeout=120.0)
        recorder.close()  # finalised; the plant zeroed the coils when the session ended
    return {
        'samples': recorder.counts[CURRENTS_TOPIC],
        'simulated_s': result.recorded_s,
        'wall_s': result.wall_s,
        'timeouts': plant.counters['timeouts'],
        'crashed': result.crashed,
        'crash_reason': result.reason,
        'driver': plant.counters,
        'dropped': writer.dropped,
        'stopped': result.stopped,
    }


def _run_board(args: argparse.Namespace, bag: Path, stop=None) -> dict:
    n_sensors = board_sensors(args)
    if max(args.sensors) >= n_sensors or min(args.sensors) < 0:
        raise UsageError(
            f'--sensors must be in 0 .. {n_sensors - 1} (the board has '
            f'{n_sensors}), got {args.sensors}'
        )
    if args.board:
        return run_board_experiment(args, bag, args.board, n_sensors, stop)
    child, port = start_virtual_board(args.params, args.magnet)
    try:
        return run_board_experiment(args, bag, port, n_sensors, stop)
    finally:
        stop_child(child)


def _run(args: argparse.Namespace) -> int:
    limit_blas_threads(1)  # small solves: see limit_blas_threads
    v4x_pc = args.firmware == 'v4x_pc'
    if v4x_pc:
        from maglev_ros.cli.lab_v4x_pc import check_v4x_pc, run_v4x_pc_session

        check_v4x_pc(args)
    else:
        _check(args)
    out = Path(args.out or time.strftime('lab_%Y%m%d_%H%M%S'))
    bag = out / 'bag'
    if args.board and not Path(args.board).exists():
        raise UsageError(
            f'--board {args.board}: no such device; is the board plugged in '
            f'(ls /dev/ttyACM*), or leave --board out for a virtual board'
        )
    if bag.exists():
        if not args.overwrite:
            raise UsageError(f'{bag} exists already; choose another --out or add --overwrite')
        if not is_bag_directory(bag):
            raise UsageError(f'{bag} is not a bag (it holds other files); not removing it')
        shutil.rmtree(bag)
    out.mkdir(parents=True, exist_ok=True)
    if v4x_pc:
        return run_v4x_pc_session(args, out, bag)
    if closed_loop(args):
        from maglev_ros.cli.closed_loop_lab import run_session

        return run_session(args, out, bag)
    board = on_board(args)
    if board:
        where = (
            args.board
            if args.board
            else f'a virtual board ({args.params}, magnet {args.magnet}, physics plant)'
        )
        print(
            f'{PROG}: {args.duration:g} s (wall clock) on {where}, {args.excitation} '
            f'{args.amplitude:g} A on {args.pattern} at {args.command_rate:g} commands/s, '
            f'seed {args.seed}'
        )
    else:
        print(
            f'{PROG}: {args.samples} samples ({args.duration:g} s) of {args.params}, '
            f'magnet {args.magnet}, '
            f'{args.excitation} {args.amplitude:g} A on {args.pattern}, coil dynamics '
            f'{"off" if args.no_coil else "on"}, sensor delay {args.delay}, noise '
            f'{args.noise:g} T, seed {args.seed}'
        )
    # SIGINT, SIGTERM and SIGHUP end the recording; the bag is finalised, also when
    # another signal arrives during the clean-up; exit status 128 + the signal
    with StopSignals() as stop:
        try:
            stats = _run_board(args, bag, stop) if board else run_experiment(args, bag, stop)
            if stats.get('stopped'):
                raise KeyboardInterrupt
        except KeyboardInterrupt:
            name = signal.Signals(stop.signum).name if stop.signum else 'interrupted'
            print(f'{PROG}: {name}: stopped; bag finalised in {bag}', file=sys.stderr)
            return stop.exit_status or 130
    if board:
        print(
            f'recorded {stats["samples"]} board samples ({stats["simulated_s"]:.3f} s of '
            f'board time in {stats["wall_s"]:.1f} s; {stats["timeouts"]} command timeouts, '
            f'{stats["driver"]["resyncs"]} resyncs, {stats["dropped"]} dropped) -> {bag}'
        )
    else:
        rate = stats['simulated_s'] / max(stats['wall_s'], 1e-9)
        print(
            f'recorded {stats["samples"]} samples ({stats["simulated_s"]:.3f} s simulated '
            f'in {stats["wall_s"]:.1f} s, {rate:.2f} x real time; {stats["timeouts"]} '
            f'command timeouts) -> {bag}'
        )
    if stats['crashed']:
        print(
            f'warning: the magnet crashed ({stats["crash_reason"]}); identifying the '
            f'samples before the crash',
            file=sys.stderr,
        )
    dataset = load_data(bag, args.sensors, args.pattern, board=board)
    alignment = dataset.alignment
    methods = ', '.join(f'{r.topic} {r.method}' for r in alignment.reports)
    print(f'alignment: time base {alignment.base}; {methods}')
    for gap in dataset.gaps:
        print(f'gap: {gap.describe()}')
    if board and dataset.gaps:
        print(
            '(board run: a gap above is records lost between board and bag, resyncs or '
            'messages the recorder missed; filled: fields linearly, currents held)'
        )
    data = dataset.data
    result = identify(data, args.na, args.nb, args.nk, args.split, args.quiet)
    print(
        f'ARX na={args.na} nb={args.nb} nk={args.nk}, inputs {", ".join(data.input_names)}; '
        f'{data.N} samples, Ts = {data.Ts:g} s, split {args.split:g} '
        f'(validation from t = {result.validation.t0:g} s)'
    )
    print(f'{"output":<10} {"fit est. %":>11} {"fit val. %":>11}  status')
    for row in result.rows:
        status = '' if row.status == 'ok' else f'{row.status}: {row.reason}'
        line = (
            f'{row.outputs[0]:<10} {row.fit_estimation[0]:>11.2f} {row.fit_validation[0]:>11.2f}'
        )
        print(f'{line}  {status}' if status else line)
        for note in row.notes:
            print(f'{"":<10} note: {note}')
    if not args.no_plots:
        from maglev_ros.sysid import compare_plot

        for row in result.rows:
            if row.validated is None:
                continue
            i = result.validation.output_names.index(row.outputs[0])
            label = f'ARX {args.na} {args.nb} {args.nk}' + (
                ' (reduced)' if row.status == 'reduced' else ''
            )
            path = compare_plot(
                result.validation.select(outputs=[i]),
                [row.validated],
                out / f'compare_{row.outputs[0]}.png',
                labels=[label],
                ic='estimate',
            )
            print(f'wrote {path}')
    summary = {
        'run': stats,
        'args': {k: v for k, v in vars(args).items()},
        'metadata': {k: v for k, v in dataset.metadata.items()},
        'alignment': {
            'base': alignment.base,
            'methods': {r.topic: r.method for r in alignment.reports},
        },
        'data': {
            'N': data.N,
            'n_estimation': result.estimation.N,
            'n_validation': result.validation.N,
        },
        'models': [_model_entry(row, data.nu) for row in result.rows],
        'exit_status': result.exit_status,
    }
    (out / 'models.json').write_text(json.dumps(summary, indent=2, default=_plain))
    print(f'wrote {out / "models.json"}')
    return result.exit_status


def _model_entry(row, nu: int) -> dict:
    """Return the ``models.json`` entry of one output's row (NaN fits as null)."""
    entry = {
        'output': row.outputs[0],
        'status': row.status,
        'note': row.reason,
        'notes': list(row.notes),
        'fit_estimation': _finite(row.fit_estimation[0]),
        'fit_validation': _finite(row.fit_validation[0]),
    }
    if row.model is not None:
        entry['A'] = row.model.polynomial('A').tolist()
        entry['B'] = [row.model.polynomial('B', 0, j).tolist() for j in range(nu)]
        entry['theta'] = np.asarray(row.model.theta).tolist()
    return entry


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _plain(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


def main(argv: list[str] | None = None) -> int:
    """Run ``maglev-lab`` (see the module docstring).

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.
    """
    return run_command(PROG, build_parser(), _run, argv)


if __name__ == '__main__':
    raise SystemExit(main())
