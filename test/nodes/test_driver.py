import os
import re
import signal
import subprocess
import sys
import time
from collections import deque
from functools import partial

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, MagneticField
from spinning import Spinning
from std_srvs.srv import SetBool
from waiting import wait_for

from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware, V4xFirmware
from maglev_ros.hardware.packet import sendable_pwm
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.v2x_stream import record_size
from maglev_ros.hardware.virtual_board import VirtualBoard, VirtualBoardError
from maglev_ros.nodes.driver import DriverNode, DriverParameterError, build_config
from maglev_ros.nodes.messages import command_message

TIMEOUT = 15.0  # s, generous: the machine is shared
RELIABLE_DEEP = QoSProfile(depth=20000, reliability=ReliabilityPolicy.RELIABLE)


class Harness:
    """The driver node and a peer node, each spun by its own executor thread."""

    def __init__(self, ctx, port, *, n_sensors=1, listen=False, **params):
        self.port = port
        self.closed = False
        overrides = [Parameter('port', value=port), Parameter('n_sensors', value=n_sensors)]
        overrides += [Parameter(k, value=v) for k, v in params.items()]
        self.driver = DriverNode(context=ctx, parameter_overrides=overrides)
        self.peer = rclpy.create_node('driver_test_peer', context=ctx)
        self.fields = [deque() for _ in range(n_sensors)]
        self.currents = deque()
        self.diagnostics = deque(maxlen=5)
        if listen:
            for k in range(n_sensors):
                self.peer.create_subscription(
                    MagneticField,
                    f'maglev/sensor_{k}/field',
                    self._sink(self.fields[k]),
                    RELIABLE_DEEP,
                )
            self.peer.create_subscription(
                JointState, 'maglev/currents', self._sink(self.currents), RELIABLE_DEEP
            )
        self.peer.create_subscription(
            DiagnosticArray, '/diagnostics', self._sink(self.diagnostics), 10
        )
        self.commands = self.peer.create_publisher(JointState, 'maglev/currents/command', 100)
        self.enable_client = self.peer.create_client(SetBool, 'maglev/enable')
        self.spinning = Spinning(ctx, (self.driver, self.peer))
        wait_for(lambda: self.commands.get_subscription_count() > 0, what='discovery')

    @staticmethod
    def _sink(queue):
        def store(msg):
            queue.append(msg)

        return store

    def command(self, currents):
        self.commands.publish(command_message(0, [float(c) for c in currents]))

    def command_until(self, currents, board, expected):
        """Publish until the board applied ``expected`` (the first messages after
        discovery may be lost: the command subscription is best effort)."""
        deadline = time.monotonic() + TIMEOUT
        while last_accepted(board) != tuple(expected):
            assert time.monotonic() < deadline, f'command {currents} never reached the board'
            self.command(currents)
            time.sleep(0.05)

    def enable(self, flag):
        assert self.enable_client.wait_for_service(timeout_sec=TIMEOUT)
        future = self.enable_client.call_async(SetBool.Request(data=flag))
        wait_for(future.done, what='enable service')
        return future.result()

    def close(self):
        if self.closed:
            return
        self.closed = True
        self.spinning.close()
        self.driver.destroy_node()
        self.peer.destroy_node()


@pytest.fixture
def make_harness(ctx, monkeypatch):
    made = []
    close_board = VirtualBoard.close

    def close_drivers_first(board):
        # the driver lets go of its board before the board goes away: otherwise its I/O
        # thread logs the lost link after the test, outside pytest's capture
        try:
            path = board.path
        except VirtualBoardError:  # not open (any more)
            path = None
        for harness in made:
            if harness.port == path:
                harness.close()
        close_board(board)

    monkeypatch.setattr(VirtualBoard, 'close', close_drivers_first)

    def make(port, **kwargs):
        harness = Harness(ctx, port, **kwargs)
        made.append(harness)
        return harness

    yield make
    for harness in made:
        harness.close()


def v2x_board(n_sensors=1, **kwargs):
    kwargs.setdefault('startup_delay', 0.2)
    plant = LinearPlant.default(n_sensors)
    return VirtualBoard(partial(V2xFirmware, plant, n_sensors, **kwargs)), plant


def last_accepted(board):
    with board.lock:
        return board.firmware.accepted[-1][1] if board.firmware.accepted else None


@pytest.mark.parametrize('n_sensors', [1, 3])
def test_published_fields_equal_the_model_in_tesla(make_harness, n_sensors):
    board, plant = v2x_board(n_sensors)
    with board:
        scaling = CurrentScaling(counts_per_ampere=1000.0)
        h = make_harness(
            board.path,
            n_sensors=n_sensors,
            listen=True,
            counts_per_ampere=1000.0,
            start_enabled=True,
            command_timeout=1.0,
        )
        h.command_until([0.5, -0.25, 1.5, -4.0], board, (500, -250, 1500, -4000))
        wait_for(lambda: sum(any(c.effort) for c in list(h.currents)) > 200, what='samples')
        currents = {
            (m.header.stamp.sec, m.header.stamp.nanosec): m.effort for m in list(h.currents)
        }
        now = time.time()  # when the newest stamp was heard (the checks below take seconds)
        checked = 0
        for k in range(n_sensors):
            for msg in list(h.fields[k]):
                assert msg.header.frame_id == f'maglev_sensor_{k}'
                key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
                if key not in currents:
                    continue
                counts = scaling.to_counts(np.array(currents[key]))
                model_t = plant(counts, 0.0)[k].astype(np.float32).astype(np.float64) * 1e-3
                field = msg.magnetic_field
                np.testing.assert_array_equal([field.x, field.y, field.z], model_t)
                checked += 1
        assert checked > 200 * n_sensors
        stamps = np.array([s * 10**9 + ns for s, ns in currents])
        assert np.all(np.diff(stamps) > 0)
        assert abs(stamps[-1] * 1e-9 - now) < 5.0  # board clock mapped to ROS time


def test_current_sweep_reaches_the_board_as_scaled_pwm(make_harness):
    board, _ = v2x_board()
    with board:
        h = make_harness(
            board.path,
            supply_voltage=12.0,
            coil_resistance=3.0,
            start_enabled=True,
            command_timeout=1.0,
        )
        scaling = h.driver.config.scaling
        h.command_until([0.0, 0.0, 0.0, 0.01], board, (0, 0, 0, 10))  # 1024 counts/A
        counts = np.arange(-4096, 4097)
        unsendable = counts[counts % 256 == 0x3E]
        sweep = np.unique(
            np.concatenate(
                [counts[::97], unsendable, unsendable - 1, unsendable + 1, [-4096, 4096]]
            )
        )
        amps = scaling.to_current(sweep)  # covers the whole PWM range
        for j, current in enumerate(amps):
            command = np.roll([current, -current / 2, 0.0, 0.01], j % 4)
            expected = tuple(int(c) for c in sendable_pwm(scaling.to_counts(command)))
            h.command(command)
            wait_for(lambda e=expected: last_accepted(board) == e, what=f'command {command}')
            exact = scaling.to_counts(command)
            assert np.abs(np.array(expected) - exact).max() <= 1
        assert h.driver.counters['commands_rejected'] == 0


def test_bad_commands_never_reach_the_wire(make_harness):
    board, _ = v2x_board()
    with board:
        h = make_harness(
            board.path,
            counts_per_ampere=1000.0,
            current_limit=2.0,
            start_enabled=True,
            command_timeout=1.0,
        )
        h.command_until([0.1, 0.1, 0.1, 0.1], board, (100, 100, 100, 100))
        with board.lock:
            before = len(board.firmware.accepted)
        h.command([np.nan, 0.0, 0.0, 0.0])
        h.command([0.0, np.inf, 0.0, 0.0])
        h.command([0.0, 0.0, -np.inf, 0.0])
        h.command([0.2, 0.2, 0.2])
        h.command([0.2, 0.2, 0.2, 0.2, 0.2])
        h.command([0.3, 0.3, 0.3, 0.3])
        wait_for(lambda: last_accepted(board) == (300, 300, 300, 300))
        with board.lock:
            between = list(board.firmware.accepted)[before:]
        assert [pwm for _, pwm in between] == [(300, 300, 300, 300)]
        h.command([100.0, -5.0, 1.0, 0.0])  # clamped to the 2 A limit
        wait_for(lambda: last_accepted(board) == (2000, -2000, 1000, 0))
        assert h.driver.counters['commands_rejected'] == 5
        assert h.driver.counters['commands_clamped'] == 1


def test_disabled_means_zero_currents(make_harness):
    board, _ = v2x_board()
    with board:
        h = make_harness(board.path, counts_per_ampere=1000.0, command_timeout=1.0)
        assert not h.driver.enabled

        def accepted():
            with board.lock:
                return [pwm for _, pwm in board.firmware.accepted]

        def command_while_disabled():
            start = len(accepted())
            while len(accepted()) < start + 3:
                h.command([1.0, 1.0, 1.0, 1.0])
                time.sleep(0.05)
            return accepted()[start:]

        assert set(command_while_disabled()) == {(0, 0, 0, 0)}
        assert h.enable(True).success
        h.command_until([1.0, 1.0, 1.0, 1.0], board, (1000, 1000, 1000, 1000))
        response = h.enable(False)
        assert response.success and 'zero' in response.message
        wait_for(lambda: last_accepted(board) == (0, 0, 0, 0))
        assert set(command_while_disabled()) == {(0, 0, 0, 0)}


def test_driver_timeout_zeroes_the_coils(make_harness):
    board, _ = v2x_board(watchdog=5.0)
    with board:
        h = make_harness(
            board.path, counts_per_ampere=1000.0, start_enabled=True, command_timeout=0.1
        )
        h.command_until([0.7, 0.7, 0.7, 0.7], board, (700, 700, 700, 700))
        wait_for(lambda: last_accepted(board) == (0, 0, 0, 0), what='driver timeout')
        assert h.driver.counters['timeouts'] >= 1
        with board.lock:
            assert board.firmware.watchdog_trips == 0
            assert list(board.firmware.pwm) == [0, 0, 0, 0]


def test_board_watchdog_zeroes_the_coils(make_harness):
    board, _ = v2x_board(watchdog=0.3)
    with board:
        h = make_harness(
            board.path, counts_per_ampere=1000.0, start_enabled=True, command_timeout=1.0
        )
        h.command_until([0.7, 0.7, 0.7, 0.7], board, (700, 700, 700, 700))
        assert board.wait_until(lambda b: b.firmware.watchdog_trips == 1, TIMEOUT)
        with board.lock:
            assert list(board.firmware.pwm) == [0, 0, 0, 0]
        assert h.driver.counters['timeouts'] == 0


def test_faults_cost_at_most_the_damaged_records(make_harness):
    size = record_size(1)
    clock_start = (1 << 32) - 1_500_000  # wraps about 1.3 s after the loop starts
    board, _ = v2x_board(clock_start_us=clock_start)
    with board:
        board.tamper_next_burst(lambda b: b[7:])  # the driver starts mid-record
        h = make_harness(board.path)
        wait_for(lambda: h.driver.counters['records'] > 500, what='records')
        garbage = b'\x3e\x3c\x00\xff garbage' * 4
        board.inject(garbage)
        board.tamper_next_burst(lambda b: b[: 2 * size + 5] + b[3 * size :])  # truncated
        wait_for(lambda: h.driver.decoder_stats.wraps == 1, what='the timestamp wrap')
        board.pause()  # let the driver drain what is in flight
        with board.lock:
            written = board.firmware.records_since_open
        # drained: every record on the wire decoded (a loaded machine may lag behind)
        wait_for(
            lambda: (
                h.driver.decoder_stats.records >= written - 2 - 1
                and h.driver.stream.buffered == size
            ),
            what='the driver to drain',
        )
        time.sleep(0.1)
        stats = h.driver.decoder_stats
        assert board.status.bytes_dropped == 0  # the driver kept up: every fault is ours
        assert stats.dropped_bytes == (size - 7) + len(garbage) + 5
        assert stats.resyncs == 2 and stats.wraps == 1
        # every record but the two damaged ones (and the one held back for
        # confirmation) was published
        assert h.driver.counters['records'] == stats.records == written - 2 - 1


def test_unplug_and_replug_recover_without_restart(make_harness):
    board, _ = v2x_board()
    with board:
        h = make_harness(board.path, reconnect_min_delay=0.1, reconnect_max_delay=0.4)
        wait_for(lambda: h.driver.counters['records'] > 100)
        board.unplug()
        wait_for(lambda: h.driver.link_state != 'connected', what='link loss')
        time.sleep(0.5)
        board.plug()
        wait_for(lambda: h.driver.counters['reconnects'] == 1, what='reconnect')
        before = h.driver.counters['records']
        wait_for(lambda: h.driver.counters['records'] > before + 100, what='records after replug')
        assert h.driver.link_state == 'connected'
        assert last_accepted(board) == (0, 0, 0, 0)  # zero sent on connect


def test_diagnostics(make_harness):
    board, _ = v2x_board()
    with board:
        h = make_harness(board.path, diagnostics_period=0.2)
        wait_for(lambda: h.driver.counters['records'] > 2000)
        h.diagnostics.clear()
        wait_for(lambda: len(h.diagnostics) > 0, what='diagnostics')
        status = h.diagnostics[-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert status.level == DiagnosticStatus.OK and status.hardware_id == board.path
        assert values['link state'] == 'connected'
        assert float(values['records/s']) > 1000
        for key in ('resyncs', 'dropped bytes', 'command rate (1/s)', 'timeouts', 'reconnects'):
            assert key in values


def test_v4x_telemetry_with_informational_lines(make_harness):
    plant = LinearPlant.default(2)
    scaling = CurrentScaling(1000.0)
    amps = np.array([0.4, -0.4, 0.2, -0.2])

    def current(t):
        return amps if t > 2.3 else np.zeros(4)

    factory = partial(
        V4xFirmware,
        plant,
        2,
        current=current,
        scaling=scaling,
        log_period=0.002,
        startup_delay=0.2,
    )
    with VirtualBoard(factory) as board:
        h = make_harness(board.path, n_sensors=2, firmware='v4x', listen=True)
        wait_for(lambda: any(m.effort[0] > 0 for m in list(h.currents)), what='V4x samples')
        with board.lock:
            board.firmware.inject_freeze()
        wait_for(lambda: h.driver.last_info == 'I2C and sensor reset complete', what='info lines')
        assert h.driver.counters['info_messages'] == 6
        msg = h.currents[-1]
        np.testing.assert_array_equal(msg.effort, amps)
        expected = (plant(scaling.to_counts(amps), 0) - plant(np.zeros(4), 0)) * 1e-3
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        for k in range(2):
            field = next(
                m for m in h.fields[k] if (m.header.stamp.sec, m.header.stamp.nanosec) == stamp
            )
            got = [field.magnetic_field.x, field.magnetic_field.y, field.magnetic_field.z]
            np.testing.assert_allclose(got, expected[k], atol=1e-9)  # 6 decimals in mT
        deadline = time.monotonic() + TIMEOUT
        while h.driver.counters['commands_ignored'] == 0:  # read-only firmware: ignored
            assert time.monotonic() < deadline, 'the command never reached the driver'
            h.command([1.0, 1.0, 1.0, 1.0])
            time.sleep(0.05)
        assert h.driver.counters['commands_sent'] == 0


def _base_values(**changes):
    values = {
        'port': '/dev/ttyACM0',
        'firmware': 'v2x',
        'baudrate': 0,
        'n_sensors': 1,
        'sensor_frames': [],
        'supply_voltage': 12.0,
        'coil_resistance': 4.0,
        'counts_per_ampere': 0.0,
        'current_limit': 0.0,
        'command_timeout': 0.1,
        'start_enabled': False,
        'reconnect_min_delay': 0.2,
        'reconnect_max_delay': 5.0,
        'diagnostics_period': 1.0,
        'confirm_records': True,
    }
    return values | changes


def test_config_defaults():
    config = build_config(_base_values())
    assert config.baudrate == 9600 and config.sensor_frames == ('maglev_sensor_0',)
    assert config.scaling.counts_per_ampere == pytest.approx(4096 * 4 / 12)
    assert config.current_limit == pytest.approx(3.0)
    assert build_config(_base_values(firmware='v4x')).baudrate == 115200


@pytest.mark.parametrize(
    'changes, match',
    [
        (
            {'firmware': 'v5x'},
            r"firmware must be 'v2x', 'v4x' or 'v4x_pc' \(V4x PC control\), got 'v5x'",
        ),
        ({'port': ''}, 'port must be a device path'),
        ({'n_sensors': 0}, 'n_sensors must be in 1 .. 64, got 0'),
        ({'sensor_frames': ['a', 'b']}, r'sensor_frames must name 1 frames'),
        ({'supply_voltage': -12.0}, 'supply_voltage must be a positive finite number'),
        ({'counts_per_ampere': float('nan')}, 'counts_per_ampere must be a positive'),
        ({'current_limit': -1.0}, 'current_limit must be a positive'),
        ({'command_timeout': 0.0}, 'command_timeout must be a positive'),
        ({'reconnect_max_delay': 0.1}, 'reconnect_max_delay must be >= reconnect_min_delay'),
    ],
)
def test_config_errors(changes, match):
    with pytest.raises(DriverParameterError, match=match):
        build_config(_base_values(**changes))


def test_node_rejects_invalid_parameters(ctx):
    with pytest.raises(DriverParameterError, match='n_sensors must be in 1 .. 64, got 0'):
        DriverNode(context=ctx, parameter_overrides=[Parameter('n_sensors', value=0)])


def test_node_refuses_the_removed_intra_process(ctx):
    with pytest.raises(DriverParameterError, match='intra_process was removed: a loop process'):
        DriverNode(context=ctx, parameter_overrides=[Parameter('intra_process', value=True)])


def test_commands_are_taken_by_coil_name(make_harness):
    board, _ = v2x_board()
    with board:
        h = make_harness(
            board.path, counts_per_ampere=1000.0, start_enabled=True, command_timeout=1.0
        )

        def publish_until(msg, expected):
            deadline = time.monotonic() + TIMEOUT
            while last_accepted(board) != expected:
                assert time.monotonic() < deadline, f'{msg} never reached the board'
                h.commands.publish(msg)
                time.sleep(0.05)

        h.command_until([0.1, 0.2, 0.3, 0.4], board, (100, 200, 300, 400))
        msg = command_message(0, [0.8, 0.7, 0.6, 0.5])
        msg.name = ['y-', 'y+', 'x-', 'x+']  # another order: the efforts follow their names
        publish_until(msg, (500, 600, 700, 800))
        msg.name = []  # no names: the contract's order x+ x- y+ y-
        publish_until(msg, (800, 700, 600, 500))
        before = h.driver.counters['commands_rejected']
        msg.name = ['a', 'b', 'c', 'd']  # not the coils: rejected, counted, nothing sent
        deadline = time.monotonic() + TIMEOUT
        while h.driver.counters['commands_rejected'] == before:
            assert time.monotonic() < deadline, 'the misnamed command never reached the driver'
            h.commands.publish(msg)
            time.sleep(0.05)
        assert last_accepted(board) == (800, 700, 600, 500)


def test_runtime_parameter_validation(make_harness):
    board, _ = v2x_board()
    with board:
        h = make_harness(board.path)
        result = h.driver.set_parameters([Parameter('command_timeout', value=-1.0)])[0]
        assert not result.successful and 'command_timeout must be a positive' in result.reason
        assert h.driver.set_parameters([Parameter('current_limit', value=1.5)])[0].successful
        assert h.driver.config.current_limit == 1.5
        assert not h.driver.set_parameters([Parameter('port', value='/dev/null')])[0].successful


def _driver_process(port, domain, *extra):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    cmd = [sys.executable, '-m', 'maglev_ros.nodes.driver', '--ros-args', '-p', f'port:={port}']
    for item in extra:
        cmd += ['-p', item]
    return subprocess.Popen(
        cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


@pytest.mark.parametrize('repeat', [False, True], ids=['once', 'repeated'])
@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_shutdown_by_signal_sends_zeros(ctx, domain, signum, repeat):
    """Zero currents on SIGTERM/SIGINT/SIGHUP, quietly, also with more signals (issue 11 item 5).

    The I/O thread stops before the context shuts down: no ERROR or FATAL line
    (its publish used to fail and the generic error path sent the zeros).
    """
    board, _ = v2x_board()
    with board:
        proc = _driver_process(
            board.path,
            domain,
            'start_enabled:=true',
            'command_timeout:=1.0',
            'counts_per_ampere:=1000.0',
        )
        try:
            peer = rclpy.create_node('driver_signal_peer', context=ctx)
            pub = peer.create_publisher(JointState, 'maglev/currents/command', 10)
            deadline = time.monotonic() + 30.0
            while last_accepted(board) != (600, 600, 600, 600):
                assert time.monotonic() < deadline, 'the driver process never applied a command'
                assert proc.poll() is None, proc.stdout.read()
                pub.publish(command_message(0, [0.6] * 4))
                time.sleep(0.05)
            time.sleep(0.5)  # records flow
            proc.send_signal(signum)
            while repeat and proc.poll() is None:  # more signals during the clean-up
                time.sleep(0.003)
                proc.send_signal(signum)
            assert proc.wait(timeout=15.0) == 0, proc.stdout.read()
            output = proc.stdout.read()
            problems = re.findall(r'.*(?:\[ERROR\]|\[FATAL\]|Traceback).*', output)
            assert not problems, output
            assert last_accepted(board) == (0, 0, 0, 0)
            with board.lock:
                assert list(board.firmware.pwm) == [0, 0, 0, 0]
            peer.destroy_node()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def test_main_exits_2_on_invalid_parameters(domain):
    proc = _driver_process('/dev/null', domain, 'firmware:=v9x')
    out, _ = proc.communicate(timeout=30.0)
    assert proc.returncode == 2
    assert "firmware must be 'v2x', 'v4x' or 'v4x_pc' (V4x PC control), got 'v9x'" in out


def test_unexpected_error_zeroes_the_coils_and_reconnects(make_harness, monkeypatch):
    board, _ = v2x_board()
    with board:
        h = make_harness(
            board.path, counts_per_ampere=1000.0, start_enabled=True, command_timeout=1.0
        )
        h.command_until([0.9, 0.9, 0.9, 0.9], board, (900, 900, 900, 900))
        from maglev_ros.hardware.v2x_stream import RecordDecoder

        original = RecordDecoder.feed
        failed = []

        def feed_once_broken(self, data):
            if not failed:
                failed.append(True)
                raise RuntimeError('simulated decoder bug')
            return original(self, data)

        monkeypatch.setattr(RecordDecoder, 'feed', feed_once_broken)
        wait_for(lambda: h.driver.counters['io_errors'] == 1, what='the error')
        wait_for(lambda: last_accepted(board) == (0, 0, 0, 0), what='zero currents')
        wait_for(lambda: h.driver.counters['reconnects'] == 1, what='reconnect')
        before = h.driver.counters['records']
        wait_for(lambda: h.driver.counters['records'] > before + 100, what='records again')


def test_published_fields_equal_the_physics_model_in_tesla(make_harness):
    from maglev_ros.hardware.physics_plant import make_simulator_plant

    plant = make_simulator_plant('fixed', scaling=CurrentScaling(1000.0))
    model, pose = plant.simulator.model, plant.simulator.state
    with VirtualBoard(partial(V2xFirmware, plant, 3, startup_delay=0.2)) as board:
        h = make_harness(
            board.path,
            n_sensors=3,
            listen=True,
            counts_per_ampere=1000.0,
            start_enabled=True,
            command_timeout=1.0,
        )
        h.command_until([0.5, -0.5, 1.0, -1.0], board, (500, -500, 1000, -1000))
        wait_for(lambda: sum(any(c.effort) for c in list(h.currents)) > 100, what='samples')
        currents = {
            (m.header.stamp.sec, m.header.stamp.nanosec): m.effort for m in list(h.currents)
        }
        checked = 0
        for k in range(3):
            for msg in list(h.fields[k]):
                effort = currents.get((msg.header.stamp.sec, msg.header.stamp.nanosec))
                if effort is None:
                    continue
                model_mt = model.measurement(pose, np.array(effort)).reshape(3, 3)[k] * 1e3
                model_t = model_mt.astype(np.float32).astype(np.float64) * 1e-3  # as sent
                field = msg.magnetic_field
                np.testing.assert_array_equal([field.x, field.y, field.z], model_t)
                checked += 1
        assert checked > 300


def test_unconfirmed_records_are_published_at_once(make_harness):
    size = record_size(1)
    board, _ = v2x_board()
    with board:
        board.tamper_next_burst(lambda b: b[7:])  # mid-burst start
        h = make_harness(board.path, confirm_records=False)
        wait_for(lambda: h.driver.counters['records'] > 500, what='records')
        garbage = bytes(range(256)) * 2
        board.inject(garbage)
        # relocked behind the garbage: until records follow it, the decoder keeps its
        # last bytes (they may yet begin a run that extends backwards into them)
        wait_for(
            lambda: h.driver.decoder_stats.resyncs == 1 and h.driver.decoder_stats.locked,
            what='the resync and the lock behind the garbage',
        )
        board.pause()
        with board.lock:
            written = board.firmware.records_since_open
        # drained: every record on the wire decoded (a loaded machine may lag behind)
        wait_for(
            lambda: (
                h.driver.decoder_stats.records >= written - 1 and h.driver.stream.buffered == 0
            ),
            what='the driver to drain',
        )
        time.sleep(0.1)
        stats = h.driver.decoder_stats
        assert stats.dropped_bytes == (size - 7) + len(garbage)
        # nothing held back: all but the partial first record are published
        assert h.driver.counters['records'] == stats.records == written - 1
