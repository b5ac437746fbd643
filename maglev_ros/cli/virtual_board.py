"""maglev-virtual-board: a virtual Maggy board on a pseudo-terminal.

Prints the stable device path, then emulates the board until SIGINT or
SIGTERM. Examples::

    maglev-virtual-board                       # V2x, 1 sensor, linear plant
    maglev-virtual-board --sensors 3 --link /tmp/ttyMAGGY0
    maglev-virtual-board --firmware v4x --log-period 0.01
    maglev-virtual-board --plant physics --magnet fixed    # the physics core, 3 sensors
    maglev-virtual-board --plant physics --magnet free --noise 1e-4 --quantization 0.098e-3
    maglev-virtual-board --plant mypkg.plants:make_plant   # factory(n_sensors)
    maglev-virtual-board --firmware v4x_pc --magnet free   # V4x PC control, physics plant
    maglev-virtual-board --firmware v4x_pc --magnet free --truth /tmp/truth.csv

``--truth FILE`` (physics plant) writes the magnet's true pose as CSV every
2 ms of board time: ``t_s,x_m,y_m,z_m,alpha_rad,beta_rad,crashed,monotonic_s``
(board time since power-up, the pose, 1 once the magnet crashed, and the
machine's monotonic clock when the row was taken, to match a host's times):
what a host cannot read from the board, the check of a closed loop against it.

``--firmware v4x_pc`` emulates the V4x PC-control firmware (COBS requests,
docs/boards.md) on the physics plant by default, with the TLV493D's noise
(0.1 mT) and resolution (0.098 mT) unless given: without noise a static field
reads identically 20 times in a row and the firmware resets its sensor.
The board calibrates with the magnet absent unless ``--magnet-at-power-up present``;
``--place-after S`` puts the free magnet in place (at rest at its equilibrium) S
seconds after the board's set-up, as a hand would once the host has measured
the board without it (``maglev-lab --firmware v4x_pc`` does); default 0: at the
end of set-up.

Exit status: 0 after a signal, 2 for bad arguments (one line on stderr).
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from functools import partial
from time import monotonic

from maglev_ros.frozen_heap import frozen_heap
from maglev_ros.hardware.firmware import LinearPlant, Plant, V2xFirmware, V4xFirmware
from maglev_ros.hardware.physics_plant import MAGNET_MODES, SimulatorPlant, make_simulator_plant
from maglev_ros.hardware.scaling import V4X_PWM_FULL_SCALE, CurrentScaling
from maglev_ros.hardware.v4x_pc_firmware import V4xPcFirmware
from maglev_ros.hardware.virtual_board import VirtualBoard
from maglev_ros.realtime_priority import fifo_priority

from .usage import Parser, UsageError, check_output_file, non_negative_float, run_command

__all__ = ['build_parser', 'load_plant', 'main']

PROG = 'maglev-virtual-board'
FIRMWARES = ('v2x', 'v4x', 'v4x_pc')
V4X_PC_NOISE = 1e-4  # T rms: the TLV493D's noise, the default of a V4x PC-control board
V4X_PC_QUANTIZATION = 0.098e-3  # T per LSB of the TLV493D


def _integer_from(low: int):
    """Argparse type: an integer >= ``low``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None
        if value < low:
            raise argparse.ArgumentTypeError(f'must be >= {low}, got {value}')
        return value

    return parse


_positive_int = _integer_from(1)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected seconds, got {text!r}') from None
    if not value >= 0 or value == float('inf'):
        raise argparse.ArgumentTypeError(f'must be finite and >= 0, got {text!r}')
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not 0 < value < float('inf'):
        raise argparse.ArgumentTypeError(f'must be a positive finite number, got {text!r}')
    return value


def _clock(text: str) -> int:
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None
    if not 0 <= value < 1 << 32:
        raise argparse.ArgumentTypeError(f'must be in 0 .. 4294967295, got {value}')
    return value


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-virtual-board``."""
    parser = Parser(prog=PROG, description=__doc__.split('\n\n')[0])
    parser.add_argument('--firmware', choices=FIRMWARES, default='v2x')
    parser.add_argument(
        '--sensors', type=_positive_int, help='number of sensors (default 1; physics: the model)'
    )
    parser.add_argument('--link', help='stable device path (symlink); default: a temp dir')
    parser.add_argument(
        '--plant',
        help="'linear', 'physics' or 'module:factory' with factory(n_sensors) -> plant(pwm, t) "
        '(default: physics for v4x_pc, else linear)',
    )
    parser.add_argument(
        '--magnet', choices=MAGNET_MODES, default='fixed', help='physics plant: magnet mode'
    )
    parser.add_argument('--params', default='maggy_v2', help='physics plant: preset or YAML')
    parser.add_argument(
        '--supply-voltage', type=_positive_float, default=12.0, help='V, PWM to current (physics)'
    )
    parser.add_argument(
        '--coil-resistance', type=_positive_float, default=4.0, help='ohm (physics)'
    )
    parser.add_argument(
        '--clock-start', type=_clock, default=0, help='uint32 us clock at power-up (V2x)'
    )
    parser.add_argument(
        '--noise',
        type=non_negative_float,
        help='T rms per axis (physics; default 0, v4x_pc: 1e-4)',
    )
    parser.add_argument(
        '--quantization',
        type=non_negative_float,
        help='T per LSB (physics; default none, v4x_pc: 0.098e-3)',
    )
    parser.add_argument(
        '--board-sensor',
        type=_integer_from(0),
        default=0,
        help="v4x_pc: which of the plant's sensors the board reads (default 0)",
    )
    parser.add_argument(
        '--magnet-at-power-up',
        choices=('absent', 'present'),
        default='absent',
        help='v4x_pc: where the magnet is while the board calibrates (default absent)',
    )
    parser.add_argument(
        '--place-after',
        type=non_negative_float,
        default=0.0,
        help='v4x_pc: s after set-up at which the magnet is put in place (default 0)',
    )
    parser.add_argument(
        '--sensor-delay', type=_integer_from(0), default=0, help='samples (physics; default 0)'
    )
    parser.add_argument('--seed', type=int, default=0, help='seed of the sensor noise (physics)')
    parser.add_argument(
        '--truth',
        metavar='FILE',
        help="physics: write the magnet's true pose as CSV every 2 ms (see above)",
    )
    parser.add_argument(
        '--realtime-priority',
        type=_integer_from(0),
        default=0,
        help='SCHED_FIFO priority of the emulator thread, 1-99 (needs the right to; '
        'default 0: the normal policy)',
    )
    parser.add_argument(
        '--exit-with-parent',
        action='store_true',
        help='stop when the process that started it ends (a host running it as its child)',
    )
    parser.add_argument('--startup-delay', type=_seconds, default=2.0, help='s after open')
    parser.add_argument('--watchdog', type=_seconds, default=1.0, help='s (V2x)')
    parser.add_argument('--log-period', type=_seconds, default=1e-3, help='s per line (V4x)')
    return parser


def _physics_plant(args: argparse.Namespace) -> SimulatorPlant:
    if args.firmware == 'v4x' and args.magnet == 'free':
        raise UsageError(
            '--magnet free needs --firmware v2x or v4x_pc (a V4x PD board takes no commands)'
        )
    from maglev_ros.physics import SensorEffects

    full_scale = V4X_PWM_FULL_SCALE if args.firmware == 'v4x_pc' else 4096
    scaling = CurrentScaling.from_supply(args.supply_voltage, args.coil_resistance, full_scale)
    sensor = SensorEffects(
        noise_rms=args.noise, quantization=args.quantization, delay_samples=args.sensor_delay
    )
    try:
        plant = make_simulator_plant(args.magnet, args.params, scaling, sensor, args.seed)
        args.setup_plant = None
        if args.firmware == 'v4x_pc' and args.magnet_at_power_up == 'absent':
            # the board calibrates on a second simulator without the levitating magnet
            args.setup_plant = make_simulator_plant(
                'absent', args.params, scaling, sensor, args.seed + 1
            )
    except (ValueError, OSError) as err:
        raise UsageError(f'--params {args.params!r}: {err}') from None
    if args.sensors is not None and args.sensors != plant.n_sensors:
        raise UsageError(
            f'--sensors must be {plant.n_sensors} for --params {args.params!r}, got {args.sensors}'
        )
    args.sensors = plant.n_sensors
    return plant


def load_plant(spec: str, n_sensors: int) -> Plant:
    """Build the plant named on the command line.

    Parameters
    ----------
    spec : str
        ``'linear'`` (``LinearPlant.default``) or ``'module:factory'``
        (``'physics'`` is handled by ``main``: it needs more options).
    n_sensors : int
        Number of sensors passed to the factory.

    Returns
    -------
    callable
        ``plant(pwm_counts (4,), time_s) -> field_mT (n_sensors, 3)``.
    """
    if spec == 'linear':
        return LinearPlant.default(n_sensors)
    module_name, sep, attr = spec.partition(':')
    if not sep or not module_name or not attr:
        raise UsageError(f"--plant must be 'linear', 'physics' or 'module:factory', got {spec!r}")
    try:
        factory = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as err:
        raise UsageError(f'--plant {spec!r} cannot be loaded: {err}') from None
    try:
        plant = factory(n_sensors)
    except Exception as err:  # a user's factory: report, do not crash
        raise UsageError(f'--plant {spec!r} failed for {n_sensors} sensors: {err}') from None
    if not callable(plant):
        raise UsageError(f'--plant {spec!r} did not return a callable plant')
    return plant


def _firmware_factory(args: argparse.Namespace, plant: Plant) -> Callable[[], object]:
    if args.place_after > 0 and getattr(args, 'setup_plant', None) is None:
        raise UsageError(
            '--place-after needs --firmware v4x_pc, --plant physics and the magnet absent '
            'at power-up (the board without the magnet until then)'
        )
    if args.firmware == 'v4x_pc':
        setup = getattr(args, 'setup_plant', None)
        if args.board_sensor >= args.sensors:
            raise UsageError(
                f"--board-sensor must be below the plant's {args.sensors} sensors, "
                f'got {args.board_sensor}'
            )
        make = partial(
            V4xPcFirmware,
            plant,
            scaling=getattr(plant, 'scaling', None),
            setup_plant=setup,
            sensor=args.board_sensor,
            place_after=args.place_after,
        )
        if isinstance(plant, (SimulatorPlant, TruthRecorder)):

            def power_up_pc() -> object:
                plant.reset()
                if setup is not None:
                    setup.reset()
                return make()

            return power_up_pc
        return make
    if args.firmware == 'v2x':
        make = partial(
            V2xFirmware,
            plant,
            args.sensors,
            clock_start_us=args.clock_start,
            startup_delay=args.startup_delay,
            watchdog=args.watchdog,
        )
    else:
        if args.log_period <= 0:
            raise UsageError('--log-period must be > 0')
        make = partial(
            V4xFirmware,
            plant,
            args.sensors,
            log_period=args.log_period,
            startup_delay=args.startup_delay,
            scaling=getattr(plant, 'scaling', None),
        )
    if not isinstance(plant, (SimulatorPlant, TruthRecorder)):
        return make

    def power_up() -> object:
        plant.reset()  # a power-up restarts the physics at its start state
        return make()

    return power_up


def main(argv: Sequence[str] | None = None) -> int:
    """Run the virtual board until SIGINT or SIGTERM.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status: 0 on a signal, 2 for bad arguments.
    """
    return run_command(PROG, build_parser(), _run, argv)


def _run(args: argparse.Namespace) -> int:
    if args.plant is None:
        args.plant = 'physics' if args.firmware == 'v4x_pc' else 'linear'
    if args.firmware == 'v4x_pc':
        args.noise = V4X_PC_NOISE if args.noise is None else args.noise
        if args.quantization is None:
            args.quantization = V4X_PC_QUANTIZATION
    args.noise = args.noise or 0.0
    args.quantization = args.quantization or 0.0
    if args.plant == 'physics':
        plant = _physics_plant(args)
    else:
        args.sensors = args.sensors or 1
        plant = load_plant(args.plant, args.sensors)
    truth = None
    if args.truth:
        if not isinstance(plant, SimulatorPlant):
            raise UsageError('--truth needs the physics plant (--plant physics)')
        check_output_file('--truth', args.truth)
        plant = truth = TruthRecorder(plant)
    if args.realtime_priority > 99:
        raise UsageError(f'--realtime-priority must be 0 to 99, got {args.realtime_priority}')
    board = VirtualBoard(
        _firmware_factory(args, plant), link=args.link, realtime_priority=args.realtime_priority
    )
    stop = threading.Event()
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        previous[signum] = signal.signal(signum, lambda *_: stop.set())
    parent = os.getppid()
    out = open(args.truth, 'w', encoding='utf-8') if truth else None  # noqa: SIM115
    try:
        if out:
            out.write('t_s,x_m,y_m,z_m,alpha_rad,beta_rad,crashed,monotonic_s\n')
        # the board's thread must keep real time: no collection of the whole heap
        # (the physics model, numba) stalls it (maglev_ros.frozen_heap)
        # the main thread at the pacing thread's priority too: holding the GIL (the truth
        # file) while descheduled, it would stall the pacing thread (priority inversion)
        with frozen_heap(), fifo_priority(args.realtime_priority), board:
            print(board.path, flush=True)
            if args.realtime_priority and board.wait_until(lambda b: b.priority_note, 0.5):
                print(f'{PROG}: {board.priority_note}', file=sys.stderr, flush=True)
            while not stop.wait(0.2):
                if args.exit_with_parent and os.getppid() != parent:
                    break  # the host is gone (a child in its own session gets no signal)
                board.check()
                if out:
                    truth.write(out, board.lock)
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if out:
            truth.write(out, board.lock)
            out.close()
    return 0


class TruthRecorder:
    """A physics plant that keeps the magnet's true pose every ``every`` samples.

    Parameters
    ----------
    plant : SimulatorPlant
        The plant it calls.
    every : int, optional
        Samples between kept poses (default 10: 2 ms at 5 kHz).
    """

    def __init__(self, plant: SimulatorPlant, every: int = 10) -> None:
        self.plant = plant
        self.every = every
        self.rows: list[tuple] = []
        self._calls = 0

    def __getattr__(self, name: str):
        return getattr(self.plant, name)

    def __call__(self, pwm, time: float):
        """Step the plant; keep ``(t, x, y, z, alpha, beta, crashed, monotonic)`` at times."""
        field = self.plant(pwm, time)
        self._calls += 1
        if self._calls % self.every == 0:
            sim = self.plant.simulator
            pose = sim.crash_state if sim.crashed and sim.crash_state is not None else sim.state
            row = (time, *pose[:5].tolist(), int(sim.crashed), monotonic())
            self.rows.append(row)
        return field

    def write(self, out, lock) -> None:
        """Write the kept rows to ``out`` (CSV) and forget them.

        Parameters
        ----------
        out : file
            The open truth file.
        lock : threading.RLock
            The virtual board's lock (the board's thread appends the rows).
        """
        with lock:
            rows, self.rows = self.rows, []
        out.writelines(','.join(f'{v:.12g}' for v in row) + '\n' for row in rows)
        out.flush()


if __name__ == '__main__':
    sys.exit(main())
