"""``maglev-lab``'s main job: the closed-loop lab session, from levitation to the seed's models.

The steps (``maglev-lab`` with the magnet ``free``, the default):

1. the lab session (:func:`~maglev_ros.loop.run_session` on the
   :class:`~maglev_ros.loop.ControlLoop` of :func:`~maglev_ros.loop.build_lab_loop`):
   the simulator (lockstep, or paced by the wall clock with ``--realtime``),
   the estimator and the LQR with its excitation; the magnet levitates and
   settles, then exactly ``--samples`` samples go to the bag
   (:class:`~maglev_ros.loop.BagRecorder`) and the online identifier
   (:class:`~maglev_ros.loop.OnlineIdentifier`);
2. the bag is converted (:func:`maglev_ros.bags.read_bag`): the x and y field
   of sensor 0, the pair inputs ``u_x``, ``u_y`` (the total command,
   ``0.5 (c+ - c-)``), the excitation ``r_x``, ``r_y`` (the IV's instruments)
   and the true position;
3. :func:`~maglev_ros.sysid.seed_models.identify_groups`: the seed's models,
   split at the middle;
4. the physics check of every SISO model against the linearisation, the online
   identifier's coefficients beside the batch ARX of the same samples, plots
   and ``models.json``.

Against a board (``--board PATH`` or ``--virtual-board``, with ``--magnet
free``): the plant of step 1 is a :class:`~maglev_ros.loop.BoardPlant` (a
virtual board in a child process), the inputs are the pair currents the board
applied (``maglev/currents``, each record's PWM), there is no true state (the
settling and the excursion are the estimate's) and the physics check allows
for a record reading its field at the end of the sample its PWM drives.
"""

from __future__ import annotations

import argparse
import gc
import json
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from maglev_ros.cli.progress import progress_bar
from maglev_ros.topics import (
    TRUE_STATE_TOPIC,
    command_channel,
    current_channel,
    excitation_channel,
    field_channel,
)

__all__ = [
    'CHECK_BAND',
    'IDENTIFIER_CHANNELS',
    'LabRun',
    'lab_settings',
    'load_closed_loop_data',
    'pair_channel',
    'run_session',
]

PROG = 'maglev-lab'
CHECK_BAND = (10.0, 300.0)  # Hz, the physics check's band (see test/sysid/test_iv_physics.py)
VIRTUAL_BOARD_STARTUP_S = 0.5  # s from the port's opening (the loop is up) to the first sample
RELATIVE = 1e-300  # guards the relative difference of exactly zero coefficients
GIL_SWITCH_S = 0.0005  # s, the interpreter's switch interval while a real-time loop runs
OBSERVER_DEPTH = 200_000  # samples a real-time observer's queue holds (40 s at 5 kHz)


def pair_channel(pair: str, channel=command_channel) -> str:
    """Channel spec of an antisymmetric pair's input ``0.5 (c+ - c-)``, named ``u_<pair>``.

    Parameters
    ----------
    pair : {'x', 'y'}
        The coil pair (x+ x- or y+ y-).
    channel : callable
        Coil index to channel spec: :func:`~maglev_ros.topics.command_channel`
        (the total command, named ``u_<pair>``),
        :func:`~maglev_ros.topics.current_channel` (the currents applied, a
        board's input, also ``u_<pair>``) or
        :func:`~maglev_ros.topics.excitation_channel` (the excitation, ``r_<pair>``).

    Returns
    -------
    str
        E.g. ``u_x=0.5*maglev/currents/command:data[0]-0.5*maglev/currents/command:data[1]``.
    """
    plus = {'x': 0, 'y': 2}[pair]
    name = 'r' if channel is excitation_channel else 'u'
    return f'{name}_{pair}=0.5*{channel(plus)}-0.5*{channel(plus + 1)}'


#: The online identifier's channels: the x and y field of sensor 0 against the pair inputs.
IDENTIFIER_CHANNELS = (
    (f'Bx_0={field_channel(0, "x")}', f'By_0={field_channel(0, "y")}'),
    (pair_channel('x'), pair_channel('y')),
)


@dataclass(frozen=True)
class LabRun:
    """What the closed-loop session did.

    Attributes
    ----------
    samples : int
        Samples recorded after settling.
    settle_s : float
        Plant time before the recording, s.
    settle_rms : ndarray, shape (3,)
        RMS of the position error over the settling's last ``settle_window_s``, m.
    settle_window_s : float
        That window, s (:func:`~maglev_ros.loop.lab.settle_window`).
    settled : bool
        Below the bound on every axis.
    simulated_s : float
        Plant time of the recording, s.
    wall_s : float
        Wall time of the recording, s.
    timeouts : int
        Command timeouts. Simulation: the controller's (its input went stale,
        zero current commanded; lockstep: none, every sample is answered);
        board: the command guard's (coils zeroed for want of a command).
    crashed : bool
    crash_reason : str
    controller : dict
        The controller's ``level``, ``message``, ``saturated``, ``timeouts``
        and the ``commands`` written while recording.
    identifier : OnlineEstimate or None
        None if it got no sample.
    overruns : int
        Real time: times the simulation fell behind and skipped ahead.
    positions : ndarray, shape (n, 3), optional
        A board run: the estimated positions over the window, m.
    dropped : dict of str to int
        Samples each observer dropped (real time: behind its queue).
    board : dict
        A board run: the plant's counters.
    """

    samples: int
    settle_s: float
    settle_rms: np.ndarray
    settle_window_s: float
    settled: bool
    simulated_s: float
    wall_s: float
    timeouts: int
    crashed: bool
    crash_reason: str
    controller: dict
    identifier: object
    overruns: int = 0
    positions: np.ndarray | None = None
    dropped: dict | None = None
    board: dict | None = None


def lab_settings(args: argparse.Namespace):
    """Return the :class:`~maglev_ros.loop.LabSettings` of the arguments.

    Parameters
    ----------
    args : argparse.Namespace
        ``maglev-lab``'s checked arguments.
    """
    from maglev_ros.control.excitation import CommandExcitation
    from maglev_ros.loop import LabSettings

    return LabSettings(
        params=args.params,
        samples=args.samples,
        settle=args.settle,
        sample_rate=args.sample_rate,
        noise=args.noise,
        quantization=args.quantization,
        sensor_delay=args.delay,
        coil_dynamics=not args.no_coil,
        field_model=args.field_model,
        seed=args.seed,
        sensors=tuple(args.sensors),
        storage=args.storage,
        filter=args.filter,
        excitation=CommandExcitation(
            args.excitation,
            args.amplitude,
            tuple(args.band),
            args.pattern,
            seed=args.seed,
            length=args.length,
        ),
        realtime=bool(getattr(args, 'realtime', False)),
        control_rate=getattr(args, 'control_rate', 1000.0),
    )


def load_closed_loop_data(bag: Path, board: bool = False):
    """Read the closed-loop record: fields, pair inputs, excitation and true position.

    Parameters
    ----------
    bag : Path
        The bag directory.
    board : bool
        A board run: no true position; ``Ts`` is the board's 200 us and gaps
        (records lost on the link) are filled and reported, as
        :func:`maglev_ros.cli.lab.load_data` does.

    Returns
    -------
    dataset : maglev_ros.bags.BagDataset
        Outputs ``Bx_0``, ``By_0`` and (simulator) ``x``, ``y``, ``z`` (T, m);
        inputs ``u_x``, ``u_y`` (total command) and ``r_x``, ``r_y`` (its
        excitation), A.
    """
    from maglev_ros.bags import read_bag

    outputs = [f'Bx_0={field_channel(0, "x")}', f'By_0={field_channel(0, "y")}']
    excitation = [pair_channel(p, excitation_channel) for p in 'xy']
    if board:
        from maglev_ros.cli.lab_board import BOARD_TS

        inputs = [pair_channel(p, current_channel) for p in 'xy'] + excitation
        return read_bag(bag, outputs, inputs, Ts=BOARD_TS, allow_gaps=True)
    inputs = [pair_channel(p) for p in 'xy'] + excitation
    outputs += [f'{a}={TRUE_STATE_TOPIC}:pose.pose.position.{a}' for a in 'xyz']
    return read_bag(bag, outputs, inputs)


def _plants(args: argparse.Namespace, Ts: float, board: bool = False) -> dict:
    """Return the true local transfer functions of the x and y pairs (the check's truth).

    A board's record holds the PWM applied over its sample and the field read
    at that sample's end: one sample less delay than a simulator's command
    (which drives the coils from the next sample), so ``--delay`` - 1 is left.
    """
    from maglev_ros.physics import CoilDynamics, linearize, make_model
    from maglev_ros.sysid.physics_check import local_plant

    model = make_model(args.params)
    linear = linearize(model).reduced()
    tau = None
    if not args.no_coil:
        coil = CoilDynamics.from_parameters(model.params)
        tau = coil.inductance / coil.resistance
    # the bag's command of sample t drives the coils over [t, t + 1): only the
    # sensor's delay is left (local_plant's convention)
    delay = args.delay - 1 if board else args.delay
    return {pair: local_plant(linear, Ts, f'B{pair}_0', pair, delay, tau) for pair in ('x', 'y')}


def run_session(args: argparse.Namespace, out: Path, bag: Path) -> int:
    """Run the closed-loop session (see the module docstring); print and write the results.

    Parameters
    ----------
    args : argparse.Namespace
        ``maglev-lab``'s checked arguments (magnet ``free``).
    out : Path
        Output directory (exists).
    bag : Path
        Bag directory to create.

    Returns
    -------
    int
        0 every model estimated (a failed residual test is reported in its
        row, not in the status: closed-loop records of the lab's length rarely
        pass them), 1 a model failed, diverges or is biased by the feedback,
        128 + the signal when stopped (the bag finalised).
    """
    from maglev_ros.cli.lab_board import on_board
    from maglev_ros.stop_signals import StopSignals

    settings = lab_settings(args)
    e = settings.excitation
    board = on_board(args)
    clock = (
        f'real time (composed, control at {args.control_rate:g} Hz)'
        if settings.realtime
        else 'lockstep'
    )
    if board:
        where = args.board or f'a virtual board ({args.params}, physics plant, magnet free)'
        clock = f'real time on {where} (composed, control at {args.control_rate:g} Hz)'
    print(
        f'{PROG}: closed loop in {clock}, {args.samples} samples ({args.duration:g} s) of '
        f'{args.params} recorded after {args.settle:g} s of levitation; '
        f'{args.filter.upper()} + LQR, '
        f'{e.signal} {e.amplitude:g} A on {e.pattern} (band {e.band[0]:g}-{e.band[1]:g} of '
        f'Nyquist) added to the command; coil dynamics {"off" if args.no_coil else "on"}, '
        f'sensor delay {args.delay}, noise {args.noise:g} T, quantisation '
        f'{args.quantization:g} T, seed {args.seed}'
    )
    bars: dict = {}

    def progress(stage: str, done: int, total: int) -> None:
        bar = bars.get(stage)
        if bar is None:
            for other in bars.values():
                other.close()
            bar = bars[stage] = progress_bar(total, stage, 'samples', args.quiet)
        bar.update(done - bar.n)

    with StopSignals() as stop:
        try:
            run = _run_loop(args, settings, bag, stop, progress)
        except (RuntimeError, OSError, ValueError) as err:  # the plant did not come up
            print(f'{PROG}: error: {err} (bag, if any, finalised in {bag})', file=sys.stderr)
            return 1
        finally:
            for bar in bars.values():
                bar.close()
        if run is None:
            name = signal.Signals(stop.signum).name if stop.signum else 'interrupted'
            print(f'{PROG}: {name}: stopped; bag finalised in {bag}', file=sys.stderr)
            return stop.exit_status or 130
    rms_um = ', '.join(f'{1e6 * v:.0f}' for v in run.settle_rms)
    print(
        f'{"settled" if run.settled else "NOT settled"} after {run.settle_s:g} s: RMS of x, y, z '
        f'{"(estimated) " if run.positions is not None else ""}'
        f'over the last {run.settle_window_s:g} s {rms_um} um'
    )
    rate = run.simulated_s / max(run.wall_s, 1e-9)
    drops = sum((run.dropped or {}).values())
    if board:
        print(
            f'recorded {run.samples} board records ({run.wall_s:.1f} s; the command guard zeroed '
            f'the coils {run.timeouts} times for want of a command; {drops} samples dropped by '
            f'the observers) -> {bag}'
        )
    else:
        misses = f'{run.timeouts} command timeouts'
        if settings.realtime:
            misses = f'{run.overruns} overruns, {drops} samples dropped by the observers'
        print(
            f'recorded {run.samples} samples ({run.simulated_s:.3f} s simulated in '
            f'{run.wall_s:.1f} s, {rate:.2f} x real time; {misses}) -> {bag}'
        )
    if run.crashed:
        print(
            f'warning: the magnet crashed ({run.crash_reason}); identifying the samples '
            'before the crash',
            file=sys.stderr,
        )
    return _identify_and_report(args, out, bag, run)


def _run_loop(args: argparse.Namespace, settings, bag: Path, stop, progress) -> LabRun | None:
    """Run the session on the simulator or on a board (a virtual one started here).

    Returns None when a stop signal ended it (the bag finalised).
    """
    from maglev_ros.cli.lab_board import (
        board_sensors,
        on_board,
        start_virtual_board,
        stop_child,
    )
    from maglev_ros.loop import BoardPlant

    if not on_board(args):
        return _session(settings, bag, stop, progress)
    n_sensors = board_sensors(args)
    burst = max(1, int(round(args.sample_rate / args.control_rate)))
    child = None
    port = args.board
    if not port:
        sensor = ('--noise', f'{args.noise!r}', '--quantization', f'{args.quantization!r}')
        sensor += ('--sensor-delay', str(args.delay), '--seed', str(args.seed))
        # the board's first sample comes this long after the loop opens the port
        child, port = start_virtual_board(args.params, 'free', sensor, VIRTUAL_BOARD_STARTUP_S)
    try:
        plant = BoardPlant(port, n_sensors, burst=burst, command_timeout=0.1)
        return _session(settings, bag, stop, progress, plant)
    finally:
        if child is not None:
            stop_child(child)


def _session(settings, bag: Path, stop, progress, plant=None) -> LabRun | None:
    """Build the loop and its observers, run the session, close the observers."""
    from maglev_ros.loop import (
        BagRecorder,
        ObserverThread,
        OnlineIdentifier,
        build_lab_loop,
        lab_plan,
        run_session,
    )
    from maglev_ros.loop.lab import loop_metadata, settle_window, simulator_metadata

    s = settings
    board = plant is not None
    loop = build_lab_loop(s, plant)
    metadata = plant.metadata() if board else simulator_metadata(s)
    metadata.update(loop_metadata(s, loop))
    recorder = BagRecorder(
        bag, s.sensors, s.storage, metadata, true_state=not board, clock=not s.realtime
    )
    orders = s.identifier_orders
    identifier = OnlineIdentifier(
        source='currents' if board else 'command',
        na=np.reshape(orders[0], (2, 2)),
        nb=np.reshape(orders[1], (2, 2)),
        nk=np.reshape(orders[2], (2, 2)),
        initial_covariance=s.initial_covariance,
    )
    paced = s.realtime or board
    observers = {'recorder': recorder, 'identifier': identifier}
    if paced:  # the loop only queues; a thread of each writes or identifies
        observers = {
            name: ObserverThread(o, OBSERVER_DEPTH, f'maglev-lab-{name}')
            for name, o in observers.items()
        }
    switch = sys.getswitchinterval()
    try:
        if paced:
            if board:
                plant.open()
            gc.freeze()  # start-up's objects stay out of the collector's way (0.1 s stalls)
            sys.setswitchinterval(GIL_SWITCH_S)  # the observers' threads hand the GIL back soon
        result = run_session(loop, lab_plan(s, board), observers, progress, lambda: stop.requested)
    finally:
        sys.setswitchinterval(switch)
        for o in observers.values():
            if isinstance(o, ObserverThread):
                o.close(timeout=120.0)
        recorder.set_metadata({'session.stopped': bool(stop.requested)})
        recorder.close()
    if result.stopped:
        return None
    plant_ = loop.plant
    # on a board a lost magnet is the controller's verdict (its estimate): coils at zero
    lost = board and result.controller['level'] == 'ERROR'
    return LabRun(
        samples=result.samples,
        settle_s=s.settle_samples / s.sample_rate,
        settle_rms=result.settle_rms,
        settle_window_s=settle_window(s) / s.sample_rate,
        settled=result.settled,
        simulated_s=result.recorded_s,
        wall_s=result.wall_s,
        timeouts=plant_.counters['timeouts'] if board else result.controller['timeouts'],
        crashed=result.crashed or lost,
        crash_reason=result.reason or (result.controller['message'] if lost else ''),
        controller={**result.controller, 'commands': result.commands},
        identifier=identifier.estimate(1.0 / s.sample_rate),
        overruns=int(getattr(plant_, 'overruns', 0)),
        positions=result.positions if board else None,
        dropped=result.dropped,
        board=plant_.counters if board else None,
    )


def _identify_and_report(args: argparse.Namespace, out: Path, bag: Path, run) -> int:
    from maglev_ros.sysid.seed_models import identify_groups, physics_deviations

    board = run.positions is not None
    dataset = load_closed_loop_data(bag, board=board)
    data = dataset.data
    positions = run.positions if board else np.asarray(data.y)[:, 2:5]
    data = data.select(outputs=[0, 1])
    z_eq = _equilibrium_height(args.params)
    error = positions - np.array([0.0, 0.0, z_eq])
    excursion = np.abs(error).max(axis=0)
    rms = np.sqrt(np.mean(error**2, axis=0))
    u = np.asarray(data.u)
    print(
        f'magnet while excited{" (estimated)" if board else ""}: largest excursion from the '
        'set-point x, y, z '
        + ', '.join(f'{1e3 * v:.3f}' for v in excursion)
        + ' mm (RMS '
        + ', '.join(f'{1e6 * v:.0f}' for v in rms)
        + f' um); pair inputs within {np.abs(u[:, :2]).max():.3f} A'
    )
    alignment = dataset.alignment
    methods = ', '.join(f'{r.topic} {r.method}' for r in alignment.reports)
    print(f'alignment: time base {alignment.base}; {methods}')
    est_n = int(round(args.split * data.N))
    print(
        f'{data.N} samples, Ts = {data.Ts:g} s: estimation {est_n}, validation '
        f'{data.N - est_n} (from t = {est_n * data.Ts:g} s); IV instruments: '
        + ('the excitation r_x, r_y' if args.instruments == 'excitation' else 'the inputs (iv4)')
    )
    with progress_bar(None, 'identifying', 'models', args.quiet) as bar:

        def step(label: str, k: int, loss: float) -> None:
            bar.set_postfix_str(label if k == 0 else f'{label}: iteration {k}')

        results = identify_groups(
            data, args.split, use_instruments=args.instruments == 'excitation', progress=step
        )
    plants = _plants(args, data.Ts, board)
    band = tuple(args.check_band)
    checks = physics_deviations(results, plants, band)
    _print_table(results, checks, band)
    _print_online(run, data)
    written = [] if args.no_plots else _plots(results, checks, plants, band, out)
    for path in written:
        print(f'wrote {path}')
    summary = _summary(args, run, dataset, results, checks, band, excursion, rms)
    (out / 'models.json').write_text(json.dumps(_plain(summary), indent=1))
    print(f'wrote {out / "models.json"}')
    return summary['exit_status']


def _equilibrium_height(params: str) -> float:
    from maglev_ros.physics import make_model
    from maglev_ros.physics.equilibria import find_equilibria

    return float(find_equilibria(make_model(params))[0].z)


def _check_text(check) -> str:
    if check is None:
        return ''
    if isinstance(check, str):
        return f'n/a ({check})'
    return check.brief()


def _print_table(results, checks: dict, band) -> None:
    print(f'{"model":<22} {"fit est. %":>11} {"fit val. %":>11}  {"physics check":<19} status')
    for item in results:
        g = item.group
        head = f'{", ".join(g.outputs)} <- {", ".join(g.inputs)}'
        print(f'{"MIMO 2x2" if g.name == "mimo" else g.name}: {head}')
        for row in item.result.rows:
            label = row.label + (
                ' (IV on r)' if row.structure == 'iv' and item.instruments else ''
            )
            est = '/'.join(_percent(v) for v in row.fit_estimation)
            val = '/'.join(_percent(v) for v in row.fit_validation)
            status = row.status if row.status == 'ok' else f'{row.status}: {row.reason}'
            check = _check_text(checks.get((g.name, row.label)))
            print(f'  {label:<20} {est:>11} {val:>11}  {check:<19} {status}')
            for note in row.notes:
                print(f'  {"":<20} note: {note}')
    excluded = sorted({f for c in checks.values() if not isinstance(c, str) for f in c.excluded})
    print(
        f'physics check: largest deviation from the linearisation (discretised, coil L/R, '
        f'sensor delay) over {band[0]:g}-{band[1]:g} Hz'
        + (
            f', without +-1 Hz around the undamped resonance at '
            f'{", ".join(f"{f:.2f}" for f in excluded)} Hz'
            if excluded
            else ''
        )
    )


def _percent(value: float) -> str:
    return 'n/a' if not np.isfinite(value) else f'{value:.2f}'


def _print_online(run, data) -> None:
    """Print the online identifier's coefficients beside the batch ARX of the same samples."""
    from maglev_ros.sysid import IdData, arx

    online = run.identifier
    if online is None:
        print('online ARX: the identifier got no sample')
        return
    model = online.model
    print(
        f'online ARX (identifier node, {online.samples} samples, forgetting factor '
        f'{online.forgetting:g}) beside batch ARX of the same samples (not detrended):'
    )
    for i, (yname, uname) in enumerate((('Bx_0', 'u_x'), ('By_0', 'u_y'))):
        na = int(model.orders.na[i, i])
        nb = int(model.orders.nb[i, i])
        nk = int(model.orders.nk[i, i])
        raw = IdData(data.y[:, i], data.u[:, i], data.Ts, [yname], [uname])
        try:
            batch = arx(raw, na, nb, nk)
        except (ValueError, np.linalg.LinAlgError) as err:  # e.g. constant data: say so, go on
            print(f'  {yname} <- {uname} (ARX {na} {nb} {nk}): no batch ARX to compare: {err}')
            continue
        a_on, b_on = model.polynomial('A', i, i)[1:], model.polynomial('B', i, i)[nk:]
        a_ba, b_ba = batch.polynomial('A')[1:], batch.polynomial('B')[nk:]
        theta_on, theta_ba = np.r_[a_on, b_on], np.r_[a_ba, b_ba]
        diff = np.abs(theta_on - theta_ba).max() / max(np.abs(theta_ba).max(), RELATIVE)
        print(
            f'  {yname} <- {uname} (ARX {na} {nb} {nk}): largest difference {diff:.1e} of the '
            f'largest coefficient'
        )
        for name, on, ba, scale in (('a', a_on, a_ba, 1.0), ('b mT/A', b_on, b_ba, 1e3)):
            for kind, values in (('online', on), ('batch', ba)):
                print(f'    {name:<7}{kind:<7}' + ' '.join(f'{scale * v:8.4f}' for v in values))


def _plots(results, checks: dict, plants: dict, band, out: Path) -> list[Path]:
    from maglev_ros.sysid import compare_plot
    from maglev_ros.sysid.physics_plot import physics_check_plot

    written = []
    for item in results:
        rows = [r for r in item.result.rows if r.validated is not None]
        if not rows:
            continue
        labels = [r.label + (' (reduced)' if r.status == 'reduced' else '') for r in rows]
        written.append(
            compare_plot(
                item.result.validation,
                [r.validated for r in rows],
                out / f'compare_{item.group.name}.png',
                labels,
                ic='estimate',
            )
        )
        if item.group.pair in plants:
            fitted = [r for r in item.result.rows if r.model is not None]
            written.append(
                physics_check_plot(
                    [r.model for r in fitted],
                    out / f'physics_{item.group.name}.png',
                    [r.label for r in fitted],
                    plants[item.group.pair],
                    band,
                    [checks.get((item.group.name, r.label)) for r in fitted],
                )
            )
    return written


def _clock_name(args: argparse.Namespace) -> str:
    from maglev_ros.cli.lab_board import on_board

    if on_board(args):
        return 'board' if args.board else 'virtual board'
    return 'realtime' if args.realtime else 'lockstep'


def _summary(args, run, dataset, results, checks, band, excursion, rms) -> dict:
    from maglev_ros.sysid import model_to_dict

    models = []
    for item in results:
        for row in item.result.rows:
            check = checks.get((item.group.name, row.label))
            entry = {
                'group': item.group.name,
                'label': row.label,
                'structure': row.structure,
                'outputs': list(item.group.outputs),
                'inputs': list(item.group.inputs),
                'instruments': list(item.instruments) if row.structure == 'iv' else [],
                'status': row.status,
                'reason': row.reason,
                'notes': list(row.notes),
                'fit_estimation': row.fit_estimation,
                'fit_validation': row.fit_validation,
                'model': None if row.model is None else model_to_dict(row.model),
            }
            if check is not None:
                entry['physics_check'] = (
                    {'error': check}
                    if isinstance(check, str)
                    else {
                        'band_hz': list(band),
                        'max_db': check.max_db,
                        'max_deg': check.max_deg,
                        'rms_db': check.rms_db,
                        'rms_deg': check.rms_deg,
                        'excluded_hz': list(check.excluded),
                        'unstable_physics_per_s': check.unstable_reference,
                        'unstable_model_per_s': check.unstable_model,
                    }
                )
            if entry['model'] is not None:
                entry['model'].pop('covariance', None)
            models.append(entry)
    online = run.identifier
    residual_only = (
        'whiteness failed',
        'independence failed',
        'whiteness and independence failed',
    )
    rows = [r for item in results for r in item.result.rows]
    status = 0 if all(r.usable or r.status in residual_only for r in rows) else 1
    return {
        'session': 'closed loop',
        'run': {
            'samples': run.samples,
            'settle_s': run.settle_s,
            'settle_rms_m': run.settle_rms,
            'settled': run.settled,
            'simulated_s': run.simulated_s,
            'wall_s': run.wall_s,
            'clock': _clock_name(args),
            'state': 'estimated' if run.positions is not None else 'true',
            'timeouts': run.timeouts,
            'overruns': run.overruns,
            'crashed': run.crashed,
            'crash_reason': run.crash_reason,
            'controller': run.controller,
            'largest_excursion_m': excursion,
            'dropped': run.dropped,
            'board': run.board,
            'rms_excursion_m': rms,
        },
        'args': dict(vars(args)),
        'metadata': dict(dataset.metadata),
        'alignment': {
            'base': dataset.alignment.base,
            'methods': {r.topic: r.method for r in dataset.alignment.reports},
        },
        'data': {
            'N': dataset.data.N,
            'n_estimation': results[0].result.estimation.N if results else 0,
            'n_validation': results[0].result.validation.N if results else 0,
        },
        'models': models,
        'online': None
        if online is None
        else {
            'samples': online.samples,
            'forgetting': online.forgetting,
            'covariance_trace': online.covariance_trace,
            'fit_percent': online.fit,
            'model': _online_dict(online.model),
        },
        'exit_status': status,
    }


def _online_dict(model) -> dict:
    from maglev_ros.sysid import model_to_dict

    entry = model_to_dict(model)
    entry.pop('covariance', None)
    return entry


def _plain(value):
    """JSON-safe copy: arrays to lists, NaN/inf to None, other objects to str."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, float):
        return value if np.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    return str(value)
