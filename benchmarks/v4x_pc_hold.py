"""Benchmark: the magnet held in real time against the virtual V4x PC-control board.

The board is ``maglev-virtual-board --firmware v4x_pc --magnet free`` (physics
plant, sensor noise 0.1 mT and resolution 0.098 mT, the firmware's baseline,
feedthrough removal and x/y low-pass on) in its own process on a pty; this
process runs the closed loop on it (:func:`maglev_ros.loop.v4x_pc_setup.run_v4x_pc_loop`:
one ``03 01 02`` round trip per sample, the KF with the board's measurement
model, the LQR) with a PRBS excitation on the pairs, then writes the bag and
runs the identification and the physics check through the board's filter
(:func:`maglev_ros.sysid.board_check.check_board_bag`).

The truth (the magnet's pose) comes from the board process (``--truth``):
the largest |x|, |y| over the loop's run is the figure. Printed: the board's
round-trip rate (measured at open, nothing else to do), the rate the loop
reached, late periods, the load (``uptime``) before and after, and the
identification table. The baseline of the rate is the board's own round trip
measured in the same run.

Run::

    python benchmarks/v4x_pc_hold.py --duration 60 --out /tmp/v4x_hold

``--emulated`` runs the same loop on the emulated firmware in this process on
simulated time (:class:`maglev_ros.hardware.emulated_port.EmulatedPort`: the
board's timing exact, as fast as the machine computes): the hold and the
identification without the machine's load in the figures.

``--plant-polarization 1.1 --plant-mass 0.9`` runs a board whose magnet is not
the believed one (a perturbed parameter file for the board; the loop believes
``--params``): the bag for ``maglev-calibrate --measurement board``.
Exit status 0 when the magnet stayed within 0.5 mm in x and y, else 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from maglev_ros.control.excitation import CommandExcitation
from maglev_ros.hardware.v4x_pc_link import V4xPcLink
from maglev_ros.hardware.v4x_pc_poller import REPLY_TIMEOUT_S
from maglev_ros.loop.sample_log import write_sample_bag
from maglev_ros.loop.v4x_pc_setup import V4xPcLoopSettings, run_v4x_pc_loop
from maglev_ros.physics import load_parameters

LIMIT_M = 0.5e-3  # |x|, |y| must stay below this


def start_board(args, out: Path) -> tuple[subprocess.Popen, str, Path, str]:
    """Start the virtual board; return the process, its port, the truth file and its params."""
    params = plant_parameters(args, out)
    truth = out / 'truth.csv'
    link = out / 'ttyMAGGY'
    from maglev_ros.cli.lab_v4x_pc import PLACE_MARGIN
    from maglev_ros.hardware.v4x_pc_feedthrough import measurement_time

    # the magnet comes once the loop has measured the board without it
    place = measurement_time(1.0 / args.rate) + PLACE_MARGIN
    cmd = [
        sys.executable, '-m', 'maglev_ros.cli.virtual_board', '--firmware', 'v4x_pc',
        '--magnet', 'free', '--params', params, '--link', str(link), '--truth', str(truth),
        '--seed', str(args.seed), '--exit-with-parent', '--place-after', f'{place:g}',
    ]  # fmt: skip
    # its own session (its own CPU share under autogroup scheduling, docs/boards.md)
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, start_new_session=True)
    path = child.stdout.readline().strip()
    if not path:
        raise SystemExit('the virtual board did not start')
    return child, path, truth, params


def plant_parameters(args, out: Path):
    """Return the board's parameter set: ``--params``, or it perturbed (written to out/)."""
    if args.plant_polarization == 1.0 and args.plant_mass == 1.0:
        return args.params
    from maglev_ros.greybox import write_parameters

    p = load_parameters(args.params)
    magnet = dataclasses.replace(
        p.magnet,
        polarization=p.magnet.polarization * args.plant_polarization,
        mass=p.magnet.mass * args.plant_mass,
    )
    note = f'{args.params} with polarization x{args.plant_polarization}, mass x{args.plant_mass}'
    return str(
        write_parameters(p.replace(magnet=magnet, name='perturbed'), out / 'plant.yaml', [note])
    )


def run_real_time(args, settings, samples, excitation, out):
    """Run the loop against maglev-virtual-board on a pty; the truth from its --truth file."""
    board: dict = {}

    def start() -> None:  # after the loop is built: the free magnet falls from set-up's end
        board['child'], board['port'], board['truth'], board['params'] = start_board(args, out)

    link = V4xPcLink(str(out / 'ttyMAGGY'), timeout=REPLY_TIMEOUT_S, open_timeout=30.0)
    t0 = time.monotonic()
    try:
        run = run_v4x_pc_loop(
            settings, link, samples, excitation, progress=_progress(args), ready=start
        )
        print(f'loop: {run.samples} samples in {time.monotonic() - t0:.1f} s; {run.reason}')
    finally:
        child = board.get('child')
        if child is not None:
            child.send_signal(signal.SIGINT)
            try:
                child.wait(timeout=30)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
    truth = np.loadtxt(board['truth'], delimiter=',', skiprows=1, ndmin=2)
    during = truth[(truth[:, 7] >= run.started) & (truth[:, 7] <= run.ended)]
    return run, during, board['params']


def run_emulated(args, settings, samples, excitation, out):
    """Run the loop on the emulated firmware in this process, on the board's simulated time."""
    from maglev_ros.hardware.emulated_port import EmulatedPort
    from maglev_ros.hardware.physics_plant import make_simulator_plant
    from maglev_ros.hardware.v4x_pc_feedthrough import measurement_time
    from maglev_ros.hardware.v4x_pc_firmware import V4xPcFirmware
    from maglev_ros.physics import SensorEffects

    params = plant_parameters(args, out)
    sensor = SensorEffects(noise_rms=1e-4, quantization=0.098e-3)
    scaling = settings.scaling
    plant = make_simulator_plant('free', params, scaling, sensor, args.seed)
    setup = make_simulator_plant('absent', params, scaling, sensor, args.seed + 1)
    place = measurement_time(1.0 / settings.sample_rate) + 0.5  # after the feedthrough's
    port = EmulatedPort(
        V4xPcFirmware(plant, scaling=scaling, setup_plant=setup, place_after=place)
    )
    link = V4xPcLink('emulated', serial_link=port, timeout=REPLY_TIMEOUT_S, clock=port.clock)
    rows = []

    def sleep(seconds: float) -> None:
        port.sleep(seconds)
        sim = plant.simulator
        rows.append((port.clock(), *sim.state[:5], float(sim.crashed), port.clock()))

    t0 = time.monotonic()
    run = run_v4x_pc_loop(
        settings, link, samples, excitation, clock=port.clock, sleep=sleep,
        progress=_progress(args),
    )  # fmt: skip
    print(f'loop: {run.samples} samples in {time.monotonic() - t0:.1f} s (emulated); {run.reason}')
    return run, np.array(rows).reshape(-1, 8), params


def _progress(args):
    def progress(done: int) -> None:
        if done % (10 * int(args.rate)) == 0:
            print(f'  {done / args.rate:5.0f} s of {args.duration:g} s', flush=True)

    return progress


def load() -> str:
    """Return the load averages (``uptime``)."""
    return ' '.join(f'{v:.2f}' for v in os.getloadavg())


def main() -> int:
    """Run the benchmark (module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--duration', type=float, default=60.0, help='s of loop (default 60)')
    p.add_argument('--rate', type=float, default=1000.0, help='samples per second (Hz)')
    p.add_argument('--params', default='maggy_v2', help='believed set (and the board plant)')
    p.add_argument('--amplitude', type=float, default=0.3, help='PRBS per pair, A (0: none)')
    p.add_argument(
        '--band', type=float, nargs=2, default=(0.0, 0.05), help='of Nyquist (default 0-25 Hz)'
    )
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--plant-polarization', type=float, default=1.0)
    p.add_argument('--plant-mass', type=float, default=1.0)
    p.add_argument('--out', help='directory for bag/, truth.csv (default: a temp dir)')
    p.add_argument(
        '--emulated', action='store_true', help='the firmware in this process, simulated time'
    )
    args = p.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix='v4x_hold_'))
    out.mkdir(parents=True, exist_ok=True)
    if (out / 'bag').exists():
        raise SystemExit(f'{out / "bag"} exists: choose another --out')
    settings = V4xPcLoopSettings(params=args.params, sample_rate=args.rate)
    samples = int(round(args.duration * args.rate))
    excitation = None
    if args.amplitude > 0:
        excitation = CommandExcitation(
            'prbs', args.amplitude, tuple(args.band), 'pairs', seed=args.seed, length=samples
        )
    print(f'load before: {load()}')
    if args.emulated:
        run, during, plant_params = run_emulated(args, settings, samples, excitation, out)
    else:
        run, during, plant_params = run_real_time(args, settings, samples, excitation, out)
    print(f'load after: {load()}')
    crashed = bool(during[:, 6].any()) if during.size else True
    peak = np.abs(during[:, 1:3]).max(axis=0) if during.size else np.full(2, np.nan)
    rms = np.sqrt(np.mean(during[:, 1:3] ** 2, axis=0)) if during.size else np.full(2, np.nan)
    print(
        f'board round trips (03 01 02, nothing else to do): {run.round_trip_rate:.0f} /s '
        f'(median; p99 {1e3 * run.round_trip_p99:.2f} ms); '
        f'loop rate reached {run.rate_reached:.1f} Hz (set {args.rate:g} Hz, ratio '
        f"{run.round_trip_rate / run.rate_reached:.2f} of the board's), late periods {run.late}"
    )
    print(
        f'magnet over {len(during)} truth rows ({run.ended - run.started:.1f} s): '
        f'max |x| {1e3 * peak[0]:.3f} mm, max |y| {1e3 * peak[1]:.3f} mm '
        f'(RMS {1e6 * rms[0]:.0f}, {1e6 * rms[1]:.0f} um); crashed: {crashed}'
    )
    bag = write_sample_bag(
        out / 'bag',
        run.log,
        (settings.sensor,),
        {
            'magnet': 'free',
            'params': plant_params,
            'believed_params': args.params,
            'firmware': 'v4x_pc',
            'measurement': 'board',
            'sample_rate': args.rate,
            'seed': args.seed,
            **(run.feedthrough.metadata() if run.feedthrough is not None else {}),
        },
    )
    if run.feedthrough is not None:
        print(f'board feedthrough measured before the magnet: {run.feedthrough.summary()}')
    print(f'wrote {bag}')
    ok = not crashed and run.samples == samples and bool(np.all(peak < LIMIT_M))
    if excitation is not None and run.samples == samples:
        from maglev_ros.sysid.board_check import check_board_bag

        data, results, checks = check_board_bag(bag, plant_params, settings.sensor)
        print(f'identification on {data.N} samples decimated to Ts = {data.Ts * 1e3:.4f} ms:')
        for item in results:
            for row in item.result.rows:
                check = checks.get((item.group.name, row.label))
                text = check.brief() if hasattr(check, 'max_db') else str(check or '')
                # an unstable model (the plant is) has no simulation fit: its k-step one
                sim = float(np.mean(row.fit_validation))
                kstep = float(np.mean(row.kstep_validation))
                fits = f'{sim:6.1f}' if np.isfinite(sim) else '   n/a'
                print(
                    f'  {item.group.name:<5} {row.label:<28} fit val. {fits} % '
                    f'({row.kstep}-step {kstep:6.1f} %) {row.status:<10} physics {text}'
                )
    print('held' if ok else 'NOT held')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
