"""The board side of ``maglev-lab``'s sessions: which board, its sensors, a virtual board.

Shared by the open-loop session (:mod:`maglev_ros.cli.lab`) and the
closed-loop one (:mod:`maglev_ros.cli.closed_loop_lab`): whether a session runs
against a board, how many sensors its records hold, and a
``maglev-virtual-board`` in a child process.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys

from maglev_ros.cli.usage import UsageError

__all__ = ['BOARD_TS', 'board_sensors', 'on_board', 'start_virtual_board', 'stop_child']

BOARD_TS = 200e-6  # s, the board's sample period (V2x and V4x)
WAIT_S = 60.0  # s, longest wait for the virtual board to exit after its output ends


def on_board(args: argparse.Namespace) -> bool:
    """Whether the session runs against a board (driver) rather than the simulator.

    Parameters
    ----------
    args : argparse.Namespace
        maglev-lab's parsed arguments.
    """
    return bool(getattr(args, 'board', None) or getattr(args, 'virtual_board', False))


def start_virtual_board(
    params: str, magnet: str, sensor_options: tuple[str, ...] = (), startup_delay: float = 0.2
) -> tuple[subprocess.Popen, str]:
    """Start ``maglev-virtual-board --plant physics`` in a child process.

    Parameters
    ----------
    params : str
        Parameter set of the physics plant.
    magnet : str
        Magnet mode (``free`` falls unless a host closes the loop).
    sensor_options : tuple of str, optional
        More options of its sensors (``--noise``, ``--quantization``,
        ``--sensor-delay``, ``--seed``).
    startup_delay : float, optional
        s from the host's opening of the port to the first sample (the
        physics starts then: a free magnet waits for the whole graph).

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
        f'{startup_delay!r}',
        *sensor_options,
    ]
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = child.stdout.readline().strip()  # the device path, once the board runs
    if not line:
        child.wait(timeout=WAIT_S)
        raise RuntimeError(f'the virtual board did not start: {child.stderr.read().strip()}')
    return child, line


def stop_child(child: subprocess.Popen) -> None:
    """Stop a child process with SIGINT (SIGKILL after 10 s) and reap it.

    Parameters
    ----------
    child : subprocess.Popen
        The child process.
    """
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
    """Sensors per board record: ``--board-sensors``, the model's, or read from the board.

    A board given by ``--board`` is probed: its records tell their sensor
    count (:func:`~maglev_ros.hardware.sensor_count.probe_sensor_count`,
    2 to 3 s); without a board, max(--sensors) + 1.

    Parameters
    ----------
    args : argparse.Namespace
        maglev-lab's parsed arguments.

    Raises
    ------
    UsageError
        If the board's stream does not tell its sensor count within 4.5 s.
    """
    if args.board_sensors is not None:
        return args.board_sensors
    if getattr(args, 'board', None):
        from maglev_ros.hardware.sensor_count import SensorCountError, probe_sensor_count

        try:
            return probe_sensor_count(args.board)
        except SensorCountError as err:
            raise UsageError(
                f'--board: {err}; is the board powered and streaming? '
                'Or give its sensor count with --board-sensors N'
            ) from None
    if args.virtual_board:
        from maglev_ros.physics import make_model

        try:
            return make_model(args.params).n_outputs // 3
        except (ValueError, OSError) as err:
            raise UsageError(f'--params {args.params!r}: {err}') from None
    return max(args.sensors) + 1
