"""The driver's board session, without ROS: samples to publish, commands to PWM, shutdown.

A virtual board on a pty (V2x with a linear plant, whose field is known from
the PWM in force, or the V4x PC-control emulator) and the session the driver
node wraps: every sample the link thread decodes is handed over by ``take``,
in order and once; commands pass the guard (rejected, clamped, disabled, timed
out) before the board sees them; ``close`` leaves zero currents.
"""

import sys
import time
from functools import partial

import numpy as np
import pytest

from maglev_ros.hardware import v4x_pc_protocol as proto
from maglev_ros.hardware.board_session import GIL_SWITCH_S, BoardSession
from maglev_ros.hardware.driver_config import driver_config
from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.serial_link import LinkError
from maglev_ros.hardware.v4x_pc_firmware import V4xPcFirmware
from maglev_ros.hardware.virtual_board import VirtualBoard

N_SENSORS = 2
TIMEOUT = 20.0  # s, generous: the machine is shared
SCALING = CurrentScaling.from_supply(12.0, 4.0, full_scale=255)  # 85 counts/A, 8-bit PWM
V4X_PC = {'firmware': 'v4x_pc', 'n_sensors': 1, 'counts_per_ampere': 0.0, 'current_limit': 0.0}


class Log:
    def __init__(self):
        self.lines = []

    def info(self, text, **_):
        self.lines.append(('info', text))

    def warning(self, text, **_):
        self.lines.append(('warning', text))

    def error(self, text, **_):
        self.lines.append(('error', text))


def config(port, **changes):
    values = {
        'port': port,
        'firmware': 'v2x',
        'baudrate': 0,
        'n_sensors': N_SENSORS,
        'sensor_frames': (),
        'supply_voltage': 12.0,
        'coil_resistance': 4.0,
        'counts_per_ampere': 1000.0,
        'current_limit': 1.0,
        'command_timeout': 1.0,
        'start_enabled': True,
        'reconnect_min_delay': 0.05,
        'reconnect_max_delay': 0.2,
        'diagnostics_period': 1.0,
        'confirm_records': False,
        'read_interval': 0.0,
        'poll_rate': 1000.0,
    }
    return driver_config(values | changes)


def wait(predicate, what):
    deadline = time.monotonic() + TIMEOUT
    while not predicate():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.005)


def accepted(board):
    with board.lock:
        return [tuple(p) for _, p in board.firmware.accepted]


def last(board):
    """The PWM of the last packet the board accepted (None before the first)."""
    pwm = accepted(board)
    return pwm[-1] if pwm else None


@pytest.fixture
def board():
    plant = LinearPlant.default(N_SENSORS)
    with VirtualBoard(partial(V2xFirmware, plant, N_SENSORS, startup_delay=0.2)) as b:
        yield b


@pytest.fixture
def session(board):
    made = BoardSession(config(board.path), Log())
    made.open()
    streaming(made)
    yield made
    made.close()


def streaming(session):
    """Wait until the link is up and records flow (a command before is not written)."""
    wait(lambda: session.counters['records'] > 0, 'the first records')


def take_until(session, n):
    """Take blocks until n samples came; return stamps and values, concatenated."""
    blocks = []
    wait(lambda: blocks.append(session.take()) or sum(len(b) for b in blocks if b) >= n, 'samples')
    blocks = [b for b in blocks if b is not None]
    return np.concatenate([b.stamps_ns for b in blocks]), np.concatenate(
        [b.values for b in blocks]
    )


def newest_currents(session):
    block = session.take()
    return None if block is None else block.values[-1, -4:].tolist()


def test_every_sample_is_taken_once_in_order_in_si_units(session):
    stamps, values = take_until(session, 2000)
    assert values.shape == (len(stamps), 3 * N_SENSORS + 4)
    assert np.all(np.diff(stamps) > 0)
    assert abs(stamps[-1] * 1e-9 - time.time()) < 5.0  # board clock mapped to the system clock
    # no command came: zero PWM, the plant's offset field (float32 mT as sent) in T
    mt = LinearPlant.default(N_SENSORS)(np.zeros(4), 0.0)
    np.testing.assert_array_equal(
        values[-1, :-4], mt.astype(np.float32).astype(float).ravel() * 1e-3
    )
    np.testing.assert_array_equal(values[:, -4:], 0.0)
    # the link counted exactly what was taken (the session stopped between the two reads)
    session.close()
    rest = session.take()
    assert session.counters['records'] == len(stamps) + (len(rest) if rest else 0)
    assert session.take() is None and session.counters['samples_dropped'] == 0


def test_commands_pass_the_guard_before_the_board(board, session):
    session.command([0.25, -0.5, 2.0, float('nan')])  # rejected: nothing written
    session.command([0.25, -0.5])  # rejected: not 4 currents
    session.reject('a command carries 4 efforts (A), got 3')  # a message it could not read
    session.command([0.25, -0.5, 2.0, 0.0])  # clamped to the 1 A limit
    wait(lambda: (250, -500, 1000, 0) in accepted(board), 'the command')
    counters = session.counters
    assert counters['commands_rejected'] == 3 and counters['commands_clamped'] == 1
    assert counters['commands_sent'] >= 2  # the zero on connecting, then the command
    warnings = [text for level, text in session.log.lines if level == 'warning']
    assert any('currents must be finite' in w for w in warnings)
    assert any('rejected command: a command carries 4 efforts' in w for w in warnings)
    assert any('clamped command' in w for w in warnings)
    # the samples show the PWM in force: the currents it implies (1000 counts/A)
    wait(lambda: newest_currents(session) == [0.25, -0.5, 1.0, 0.0], 'the applied currents')
    session.set_enabled(False)  # zero at once, and for every command while disabled
    wait(lambda: last(board) == (0, 0, 0, 0), 'zero on disable')
    session.command([0.5, 0.5, 0.5, 0.5])
    wait(lambda: session.counters['commands_sent'] >= counters['commands_sent'] + 2, 'sent')
    assert last(board) == (0, 0, 0, 0) and not session.enabled
    session.set_enabled(True)
    session.command([0.5, 0.5, 0.5, 0.5])
    wait(lambda: last(board) == (500, 500, 500, 500), 'enabled again')
    session.close()  # zero currents last
    wait(lambda: last(board) == (0, 0, 0, 0), 'zero currents on close')


def test_command_timeout_zeroes_the_coils_once(board):
    session = BoardSession(config(board.path, command_timeout=0.1), Log())
    session.open()
    try:
        streaming(session)
        session.check_timeout()  # no command yet: nothing to time out
        assert session.counters['timeouts'] == 0
        session.command([0.3, 0.3, 0.3, 0.3])
        wait(lambda: last(board) == (300, 300, 300, 300), 'the command')
        time.sleep(0.15)
        session.check_timeout()
        session.check_timeout()  # once, until the next command
        wait(lambda: last(board) == (0, 0, 0, 0), 'zero currents')
        assert session.counters['timeouts'] == 1
        assert any('no valid command for' in t for _, t in session.log.lines)
        assert session.report().message == 'command timeout: zero currents'
    finally:
        session.close()


def test_an_untaken_backlog_drops_its_oldest_samples_counted(board):
    session = BoardSession(config(board.path), Log(), max_backlog=500)
    session.open()
    try:
        wait(lambda: session.counters['samples_dropped'] > 0, 'dropped samples')
        session.close()
        block = session.take()
        records = session.counters['records']
        assert 0 < len(block) <= 500  # the newest, whole reads
        assert len(block) + session.counters['samples_dropped'] == records
        assert np.all(np.diff(block.stamps_ns) > 0)
        assert session.report().values['samples dropped'] == str(records - len(block))
    finally:
        session.close()


def test_the_board_opens_at_open_only(board):
    session = BoardSession(config(board.path), Log())
    try:
        time.sleep(0.3)
        assert not board.status.port_open and session.link.state == 'connecting'
        session.open()
        session.open()  # idempotent
        wait(lambda: session.counters['records'] > 0, 'records after open')
        assert board.status.port_open
    finally:
        session.close()
    BoardSession(config(board.path), Log()).close()  # never opened: closes cleanly


def test_v4x_pc_board_is_polled_and_reset_on_close():
    rng = np.random.default_rng(3)

    def noisy(pwm, t):  # noise: the firmware's freeze check stays quiet
        return (np.array([0.5, -0.3, 40.0]) + rng.normal(0.0, 0.01, 3))[None, :]

    def firmware():
        return V4xPcFirmware(noisy, scaling=SCALING, init_delay=0.0).power_up()

    with VirtualBoard(firmware) as board:
        assert board.wait_until(lambda b: b.firmware.running, TIMEOUT)
        switch = sys.getswitchinterval()
        session = BoardSession(config(board.path, **V4X_PC), Log())
        assert session.polled and session.stream is None
        session.open()
        try:
            assert sys.getswitchinterval() == pytest.approx(min(switch, GIL_SWITCH_S))
            stamps, values = take_until(session, 100)
            assert values.shape == (len(stamps), 7) and np.all(np.diff(stamps) > 0)
            session.command([0.5, -0.5, 0.0, 0.0])  # 85 counts/A, 8-bit
            wait(lambda: board.firmware.pwm.tolist() == [42, -42, 0, 0], 'the pair command')
            with board.lock:
                before = board.firmware.requests[proto.RESET]
        finally:
            session.close()
        assert sys.getswitchinterval() == pytest.approx(switch)
        with board.lock:
            assert board.firmware.requests[proto.RESET] > before
            assert board.firmware.pwm.tolist() == [0, 0, 0, 0]


def test_v4x_pc_open_names_the_port_that_is_no_board(tmp_path):
    path = tmp_path / 'nothing'
    session = BoardSession(config(str(path), **V4X_PC), Log())
    with pytest.raises(LinkError, match=f'cannot open {path}'):
        session.open()
    session.close()
