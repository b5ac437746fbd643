"""``maglev-lab``: the lab session as one command (pip-only friendly).

Runs the simulator (lockstep), the excitation and the recorder as three nodes on
one executor in this process, for a given simulated duration; then converts the
bag into a data set (:func:`maglev_ros.bags.read_bag`: command inputs by log
time, exact alignment), identifies one ARX model per field component against
the excitation inputs, prints the fit on estimation and validation data and
writes the plots::

    maglev-lab --duration 5 --params maggy_v2 --magnet fixed --excitation prbs --out lab/

Against a board (real time: the board sets the pace, ``--duration`` is wall-clock
seconds): ``--board PATH`` runs the driver node on a serial device instead of the
simulator; ``--virtual-board`` starts ``maglev-virtual-board --plant physics``
(``--params``, ``--magnet``) in a child process and uses it. The excitation then
runs on a wall-clock timer (``--command-rate``), the inputs are the currents the
driver reports as applied (``maglev/currents:effort[coil]``, header stamps) and the
default ARX delay is 0 (a record's field and PWM are simultaneous)::

    maglev-lab --virtual-board --magnet fixed --duration 3 --amplitude 0.2 --out lab/

Outputs in ``--out``: ``bag/`` (rosbag2, MCAP), ``models.json`` (fits and
coefficients), ``compare_<output>.png`` (validation data vs model). Exit status
0, 2 on bad input (one line on stderr), 130 when interrupted (the bag is
finalised).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from maglev_ros.cli.usage import (
    Parser,
    UsageError,
    limit_blas_threads,
    non_negative_float,
    positive_float,
    run_command,
)
from maglev_ros.excitation import PATTERNS, SIGNALS, pattern_matrix
from maglev_ros.topics import (
    AXES,
    CLOCK_TOPIC,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    TRUE_STATE_TOPIC,
    command_channel,
    current_channel,
    field_channel,
    field_topic,
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
BOARD_TS = 200e-6  # s, the board's sample period (V2x and V4x)
BOARD_READ_INTERVAL = 0.002  # s between port reads in board runs (open loop: latency is free)


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-lab``."""
    p = Parser(
        prog=PROG,
        description='Simulate, excite, record and identify: the Maggy lab session in one command.',
    )
    p.add_argument(
        '--duration',
        type=positive_float,
        default=5.0,
        help='simulated seconds to record (default 5)',
    )
    p.add_argument(
        '--params', default='maggy_v2', help='parameter set (maggy_v2, maggy_v4, or a YAML path)'
    )
    p.add_argument(
        '--magnet',
        choices=('free', 'fixed', 'absent'),
        default='fixed',
        help='levitating magnet (default fixed: no controller needed)',
    )
    p.add_argument('--field-model', choices=('fast', 'accurate', 'filament'), default='fast')
    p.add_argument('--sample-rate', type=positive_float, default=5000.0, help='Hz')
    p.add_argument('--no-coil', action='store_true', help='no coil L/R dynamics')
    p.add_argument('--delay', type=int, default=1, help='sensor delay in samples (default 1)')
    p.add_argument(
        '--noise', type=non_negative_float, default=0.0, help='sensor noise, T rms (default 0)'
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
    p.add_argument('--amplitude', type=non_negative_float, default=0.5, help='A (default 0.5)')
    p.add_argument(
        '--band',
        type=float,
        nargs=2,
        default=[0.0, 1.0],
        metavar=('LOW', 'HIGH'),
        help='band as fractions of Nyquist (default 0 1)',
    )
    p.add_argument(
        '--pattern',
        choices=PATTERNS,
        default='pairs',
        help='coil pattern (default pairs: +u on x+, -u on x-, same for y)',
    )
    p.add_argument('--length', type=int, default=8191, help='samples per excitation period')
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
    board = p.add_mutually_exclusive_group()
    board.add_argument(
        '--board',
        metavar='PATH',
        default=None,
        help='run the driver on this serial device instead of the simulator',
    )
    board.add_argument(
        '--virtual-board',
        action='store_true',
        help='start a virtual board (physics plant, --params, --magnet) in a '
        'child process and run the driver on it',
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
        help='board: excitation commands per wall-clock second, Hz (default 1000)',
    )
    return p


def on_board(args: argparse.Namespace) -> bool:
    """Whether the session runs against a board (driver) rather than the simulator."""
    return bool(getattr(args, 'board', None) or getattr(args, 'virtual_board', False))


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


def identify(data, na: int, nb: int, nk: int, split: float) -> list[dict]:
    """Estimate one ARX model per output (all inputs), fits on estimation/validation data.

    Parameters
    ----------
    data : IdData
        The experiment.
    na, nb, nk : int
        ARX orders (``nb``, ``nk`` for every input).
    split : float
        Fraction of samples for estimation.

    Returns
    -------
    list of dict
        Per output: ``output``, ``model`` (PolyModel), ``fit_estimation``,
        ``fit_validation`` (percent), ``estimation``/``validation`` (IdData),
        ``note``. An output that does not respond to the inputs (constant
        after detrending, e.g. by symmetry) gets no model and NaN fits.
    """
    from maglev_ros.sysid import arx, compare

    est_all, val_all = data.detrend().split(split)
    spread = np.std(np.asarray(est_all.y), axis=0)
    rows = []
    for i, name in enumerate(data.output_names):
        if spread[i] <= 1e-9 * spread.max():
            # e.g. Bz at the centre sensor under antisymmetric pairs: zero by symmetry
            rows.append(
                {
                    'output': name,
                    'model': None,
                    'fit_estimation': float('nan'),
                    'fit_validation': float('nan'),
                    'note': 'no response to the inputs',
                }
            )
            continue
        est, val = est_all.select(outputs=[i]), val_all.select(outputs=[i])
        nu = data.nu
        model = arx(est, na, [[nb] * nu], [[nk] * nu])
        try:
            fits = [float(compare(model, d, ic='estimate').fit[0]) for d in (est, val)]
            note = ''
        except np.linalg.LinAlgError:
            # e.g. noise-free data of a static plant (a fixed magnet on a virtual board):
            # A is not identifiable and the model's simulation diverges
            fits, note = [float('nan')] * 2, 'simulation diverged: try lower orders'
        rows.append(
            {
                'output': name,
                'model': model,
                'fit_estimation': fits[0],
                'fit_validation': fits[1],
                'estimation': est,
                'validation': val,
                'note': note,
            }
        )
    return rows


def _check(args: argparse.Namespace) -> None:
    if not 0.0 < args.split < 1.0:
        raise UsageError(f'--split must be in (0, 1), got {args.split}')
    for name in ('na', 'nb', 'length'):
        if getattr(args, name) < 1:
            raise UsageError(f'--{name} must be >= 1, got {getattr(args, name)}')
    if args.nk is None:
        args.nk = 0 if on_board(args) else 1
    if args.board_sensors is not None and args.board_sensors < 1:
        raise UsageError(f'--board-sensors must be >= 1, got {args.board_sensors}')
    if args.nk < 0 or args.delay < 0:
        raise UsageError('--nk and --delay must be >= 0')
    if not 0.0 <= args.band[0] < args.band[1] <= 1.0:
        raise UsageError(f'--band must be LOW HIGH with 0 <= LOW < HIGH <= 1, got {args.band}')


def _wait(predicate, ctx, what: str, timeout: float = WAIT_S) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if not ctx.ok():
            raise KeyboardInterrupt
        if time.monotonic() > deadline:
            raise RuntimeError(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(0.01)


def overrides(**values) -> list:
    """Return ROS parameter overrides ``name=value`` for a node built in this process."""
    from rclpy.parameter import Parameter

    return [Parameter(k, value=v) for k, v in values.items()]


def run_experiment(args: argparse.Namespace, bag: Path) -> dict:
    """Run simulator (lockstep), excitation and recorder on one executor.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``maglev-lab`` arguments.
    bag : Path
        Bag directory to create.

    Returns
    -------
    dict
        ``samples``, ``simulated_s``, ``wall_s``, ``timeouts``, ``crashed``.

    Raises
    ------
    KeyboardInterrupt
        On SIGINT/SIGTERM (the bag is finalised first).
    """
    import rclpy

    from maglev_ros.nodes.excitation import ExcitationNode
    from maglev_ros.nodes.recorder import RecorderNode
    from maglev_ros.nodes.runtime import Spinner
    from maglev_ros.nodes.simulator import SimulatorNode

    topics = [field_topic(k) for k in args.sensors] + [
        CURRENTS_TOPIC,
        COMMAND_TOPIC,
        TRUE_STATE_TOPIC,
        CLOCK_TOPIC,
    ]
    ctx = _lab_context()
    nodes, spinner = [], None
    try:
        sim = SimulatorNode(
            context=ctx,
            parameter_overrides=overrides(
                params=args.params,
                field_model=args.field_model,
                magnet=args.magnet,
                sample_rate=args.sample_rate,
                coil_dynamics=not args.no_coil,
                sensor_delay=args.delay,
                sensor_noise=args.noise,
                seed=args.seed,
                mode='lockstep',
                start_paused=True,
                sensors=list(args.sensors),
                marker_rate=0.0,
                command_timeout=5.0,
            ),
        )
        nodes.append(sim)
        excite = ExcitationNode(
            context=ctx,
            parameter_overrides=overrides(
                signal=args.excitation,
                amplitude=args.amplitude,
                band=list(args.band),
                pattern=args.pattern,
                seed=args.seed,
                length=args.length,
            ),
        )
        nodes.append(excite)
        recorder = RecorderNode(
            context=ctx,
            parameter_overrides=overrides(
                path=str(bag), storage=args.storage, topics=topics, log_clock='topic'
            ),
        )
        nodes.insert(0, recorder)  # destroyed last: finalises the bag
        spinner = Spinner(ctx, nodes)
        _wait(
            lambda: (
                len(recorder.subscribed) == len(topics)
                and recorder.metadata_complete
                and excite._pub.get_subscription_count() >= 2
                and sim._current_pub.get_subscription_count() >= 2
            ),
            ctx,
            'the node graph',
        )
        wall = time.monotonic()
        sim.set_paused(False)
        _wait(
            lambda: sim.sim.time >= args.duration or sim.sim.crashed,
            ctx,
            'the simulation',
            timeout=1e9,
        )
        sim.set_paused(True)
        wall = time.monotonic() - wall
        published = sim.counters['samples']
        _wait(
            lambda: (
                recorder.counts['/' + CURRENTS_TOPIC] >= published
                and recorder.counts['/' + COMMAND_TOPIC] >= published - 1
            ),
            ctx,
            'the recorder',
        )
        return {
            'samples': published,
            'simulated_s': sim.sim.time,
            'wall_s': wall,
            'timeouts': sim.counters['timeouts'],
            'crashed': sim.sim.crashed,
            'crash_reason': sim.sim.reason,
        }
    finally:
        if spinner is not None:
            spinner.close()
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def start_virtual_board(params: str, magnet: str) -> tuple[subprocess.Popen, str]:
    """Start ``maglev-virtual-board --plant physics`` in a child process.

    Parameters
    ----------
    params : str
        Parameter set of the physics plant.
    magnet : str
        Magnet mode (``free`` falls: nothing closes the loop here).

    Returns
    -------
    tuple of (subprocess.Popen, str)
        The child (stop it with SIGINT) and its device path.

    Raises
    ------
    RuntimeError
        If the board does not start (its error output is in the message).
    """
    cmd = [
        sys.executable,
        '-m',
        'maglev_ros.cli.virtual_board',
        '--plant',
        'physics',
        '--params',
        params,
        '--magnet',
        magnet,
        '--startup-delay',
        '0.2',
    ]
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = child.stdout.readline().strip()  # the device path, once the board runs
    if not line:
        child.wait(timeout=WAIT_S)
        raise RuntimeError(f'the virtual board did not start: {child.stderr.read().strip()}')
    return child, line


def stop_child(child: subprocess.Popen) -> None:
    """Stop a child process with SIGINT (SIGKILL after 10 s) and reap it."""
    if child.poll() is None:
        child.send_signal(signal.SIGINT)
        try:
            child.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
    for stream in (child.stdout, child.stderr):
        if stream is not None:
            stream.close()


def board_sensors(args: argparse.Namespace) -> int:
    """Sensors per board record: ``--board-sensors``, the model's, or max(--sensors) + 1."""
    if args.board_sensors is not None:
        return args.board_sensors
    if args.virtual_board:
        from maglev_ros.physics import make_model

        try:
            return make_model(args.params).n_outputs // 3
        except (ValueError, OSError) as err:
            raise UsageError(f'--params {args.params!r}: {err}') from None
    return max(args.sensors) + 1


def run_board_experiment(args: argparse.Namespace, bag: Path, port: str, n_sensors: int) -> dict:
    """Run the driver (on ``port``), excitation (timer) and recorder on one executor.

    Real time: the board sets the pace; recording lasts ``args.duration``
    wall-clock seconds from the first sample after the graph is up.

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

    Returns
    -------
    dict
        ``samples`` (currents messages recorded), ``simulated_s`` (their board
        time), ``wall_s``, ``timeouts``, ``crashed`` (False), ``crash_reason``,
        ``driver`` (the driver's counters).

    Raises
    ------
    KeyboardInterrupt
        On SIGINT/SIGTERM (the bag is finalised first).
    """
    import rclpy

    from maglev_ros.nodes.driver import DriverNode
    from maglev_ros.nodes.excitation import ExcitationNode
    from maglev_ros.nodes.recorder import RecorderNode
    from maglev_ros.nodes.runtime import Spinner

    topics = [field_topic(k) for k in args.sensors] + [
        CURRENTS_TOPIC,
        COMMAND_TOPIC,
    ]
    currents_topic = '/' + CURRENTS_TOPIC
    ctx = _lab_context()
    nodes, spinner = [], None
    try:
        recorder = RecorderNode(
            context=ctx,
            parameter_overrides=overrides(
                path=str(bag), storage=args.storage, topics=topics, metadata_node='maglev_driver'
            ),
        )
        nodes.append(recorder)  # destroyed last: finalises the bag
        # an open-loop recording: latency does not matter, so the driver reads the port
        # every 2 ms (two bursts per read), which roughly halves its CPU time
        driver = DriverNode(
            context=ctx,
            parameter_overrides=overrides(
                port=port,
                n_sensors=n_sensors,
                start_enabled=True,
                command_timeout=1.0,
                read_interval=BOARD_READ_INTERVAL,
            ),
        )
        nodes.append(driver)
        spinner = Spinner(ctx, nodes)
        _wait(
            lambda: (
                len(recorder.subscribed) == len(topics) - 1
                and recorder.metadata_complete
                and driver.link_state == 'connected'
            ),
            ctx,
            'the driver and the recorder',
        )
        # the excitation starts once everything listens: its first command is recorded
        excite = ExcitationNode(
            context=ctx,
            parameter_overrides=overrides(
                signal=args.excitation,
                amplitude=args.amplitude,
                band=list(args.band),
                pattern=args.pattern,
                seed=args.seed,
                length=args.length,
                trigger='timer',
                sample_rate=args.command_rate,
            ),
        )
        nodes.append(excite)
        spinner.add_node(excite)
        _wait(
            lambda: (
                len(recorder.subscribed) == len(topics)
                and excite._pub.get_subscription_count() >= 2
            ),
            ctx,
            'the excitation',
        )
        start = recorder.counts[currents_topic]
        wall = time.monotonic()
        end = wall + args.duration
        _wait(lambda: time.monotonic() >= end, ctx, 'the recording', timeout=args.duration + 1)
        recorder.close()  # finalised; the driver zeroes the currents when destroyed
        wall = time.monotonic() - wall
        samples = recorder.counts[currents_topic] - start
        return {
            'samples': samples,
            'simulated_s': samples * BOARD_TS,
            'wall_s': wall,
            'timeouts': driver.counters['timeouts'],
            'crashed': False,
            'crash_reason': '',
            'driver': dict(driver.counters),
        }
    finally:
        if spinner is not None:
            spinner.close()
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def _run_board(args: argparse.Namespace, bag: Path) -> dict:
    n_sensors = board_sensors(args)
    if max(args.sensors) >= n_sensors or min(args.sensors) < 0:
        raise UsageError(
            f'--sensors must be in 0 .. {n_sensors - 1} (the board has '
            f'{n_sensors}), got {args.sensors}'
        )
    if args.board:
        return run_board_experiment(args, bag, args.board, n_sensors)
    child, port = start_virtual_board(args.params, args.magnet)
    try:
        return run_board_experiment(args, bag, port, n_sensors)
    finally:
        stop_child(child)


def _lab_context():
    """Return an initialised rclpy Context for the lab's nodes, discovery kept local.

    ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is set to LOCALHOST unless the
    environment sets it: the lab's graph stays on this machine.
    """
    import rclpy
    from rclpy.context import Context

    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    ctx = Context()
    rclpy.init(context=ctx, args=[])
    return ctx


def _run(args: argparse.Namespace) -> int:
    limit_blas_threads(1)  # small solves: see limit_blas_threads
    _check(args)
    out = Path(args.out or time.strftime('lab_%Y%m%d_%H%M%S'))
    bag = out / 'bag'
    if bag.exists():
        if not args.overwrite:
            raise UsageError(f'{bag} exists already; choose another --out or add --overwrite')
        if not (bag / 'metadata.yaml').is_file() and any(bag.iterdir()):
            raise UsageError(f'{bag} is not a finished bag; not removing it')
        shutil.rmtree(bag)
    out.mkdir(parents=True, exist_ok=True)
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
            f'{PROG}: {args.duration:g} s of {args.params}, magnet {args.magnet}, '
            f'{args.excitation} {args.amplitude:g} A on {args.pattern}, coil dynamics '
            f'{"off" if args.no_coil else "on"}, sensor delay {args.delay}, noise '
            f'{args.noise:g} T, seed {args.seed}'
        )
    try:
        stats = _run_board(args, bag) if board else run_experiment(args, bag)
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted; bag finalised in {bag}', file=sys.stderr)
        return 130
    if board:
        print(
            f'recorded {stats["samples"]} board samples ({stats["simulated_s"]:.3f} s of '
            f'board time in {stats["wall_s"]:.1f} s; {stats["timeouts"]} command timeouts, '
            f'{stats["driver"]["resyncs"]} resyncs) -> {bag}'
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
    rows = identify(data, args.na, args.nb, args.nk, args.split)
    print(
        f'ARX na={args.na} nb={args.nb} nk={args.nk}, inputs {", ".join(data.input_names)}; '
        f'{data.N} samples, Ts = {data.Ts:g} s, split {args.split:g}'
    )
    print(f'{"output":<10} {"fit est. %":>11} {"fit val. %":>11}')
    for row in rows:
        print(
            f'{row["output"]:<10} {row["fit_estimation"]:>11.2f} '
            f'{row["fit_validation"]:>11.2f}  {row["note"]}'
        )
    rows_fitted = [
        row for row in rows if row['model'] is not None and np.isfinite(row['fit_validation'])
    ]
    if not args.no_plots:
        from maglev_ros.sysid import compare_plot

        for row in rows_fitted:
            path = compare_plot(
                row['validation'],
                [row['model']],
                out / f'compare_{row["output"]}.png',
                labels=[f'ARX {args.na} {args.nb} {args.nk}'],
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
        'models': [
            {
                'output': r['output'],
                'fit_estimation': r['fit_estimation'],
                'fit_validation': r['fit_validation'],
                'note': r['note'],
                'A': r['model'].polynomial('A').tolist(),
                'B': [r['model'].polynomial('B', 0, j).tolist() for j in range(data.nu)],
                'theta': np.asarray(r['model'].theta).tolist(),
            }
            if r['model'] is not None
            else {'output': r['output'], 'note': r['note']}
            for r in rows
        ],
    }
    (out / 'models.json').write_text(json.dumps(summary, indent=2, default=_plain))
    print(f'wrote {out / "models.json"}')
    return 0


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
