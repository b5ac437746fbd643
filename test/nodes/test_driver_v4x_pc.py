"""The driver node against the emulated V4x PC-control board on a pty (real nodes, messages)."""

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
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, MagneticField
from spinning import Spinning
from std_srvs.srv import SetBool
from waiting import wait_for

from maglev_ros.hardware import v4x_pc_protocol as proto
from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.scaling import CurrentScaling
from maglev_ros.hardware.v4x_pc_firmware import V4xPcFirmware, adc_current
from maglev_ros.hardware.virtual_board import VirtualBoard
from maglev_ros.nodes.driver import BoardNotFoundError, DriverNode
from maglev_ros.nodes.messages import command_message

TIMEOUT = 20.0  # s, generous: the machine is shared
SCALING = CurrentScaling.from_supply(12.0, 4.0, full_scale=255)  # 85 counts/A
RELIABLE_DEEP = QoSProfile(depth=20000, reliability=ReliabilityPolicy.RELIABLE)
STEP = np.array([0.3, -0.6, 1.2])  # mT: a field change after the board's set-up


class StepPlant:
    """A noisy static field that steps by ``STEP`` at ``t_step`` (after the board's set-up).

    The noise keeps the firmware's freeze check quiet; the step makes the
    processed field differ per axis (the baseline removes the rest).
    """

    def __init__(self, t_step):
        self.t_step = t_step
        self.rng = np.random.default_rng(5)

    def __call__(self, pwm, t):
        field = np.array([0.5, -0.3, 40.0]) + (STEP if t > self.t_step else 0.0)
        return (field + self.rng.normal(0.0, 0.01, 3))[None, :]


def make_firmware():
    """A board set up before its port opens (the set-up on emulated time)."""
    firmware = V4xPcFirmware(StepPlant(0.0), scaling=SCALING, init_delay=0.0)
    firmware.plant.t_step = firmware.setup_us * 1e-6 + 0.1
    return firmware.power_up()


class PoweredThroughUnplug:
    """One firmware across unplug and plug: a board on its own supply keeps running (and
    keeps its PWM: no watchdog) while the USB cable is out. The virtual board calls this
    factory at each plug, and its clock goes on from the firmware's."""

    def __init__(self):
        self.firmware = make_firmware()
        self.plugs = 0

    def __call__(self):
        self.plugs += 1
        return self.firmware


def fw(board, attr):
    with board.lock:
        value = getattr(board.firmware, attr)
        return value.copy() if hasattr(value, 'copy') else value


def resets(board):
    with board.lock:
        return board.firmware.requests[proto.RESET]


@pytest.fixture
def board():
    with VirtualBoard(make_firmware) as vb:
        assert vb.wait_until(lambda b: b.firmware.running, TIMEOUT)
        yield vb


class Harness:
    """The driver node (firmware v4x_pc) and a peer node, each on its own executor thread."""

    def __init__(self, ctx, port, **params):
        overrides = [Parameter('port', value=port), Parameter('firmware', value='v4x_pc')]
        overrides += [Parameter(k, value=v) for k, v in params.items()]
        self.driver = DriverNode(context=ctx, parameter_overrides=overrides)
        self.peer = rclpy.create_node('driver_v4x_pc_peer', context=ctx)
        self.fields, self.currents = deque(), deque()
        self.diagnostics = deque(maxlen=5)
        self.peer.create_subscription(
            MagneticField, 'maglev/sensor_0/field', lambda m: self.fields.append(m), RELIABLE_DEEP
        )
        self.peer.create_subscription(
            JointState, 'maglev/currents', lambda m: self.currents.append(m), RELIABLE_DEEP
        )
        self.peer.create_subscription(
            DiagnosticArray, '/diagnostics', lambda m: self.diagnostics.append(m), 10
        )
        self.commands = self.peer.create_publisher(JointState, 'maglev/currents/command', 100)
        self.enable_client = self.peer.create_client(SetBool, 'maglev/enable')
        self.spinning = Spinning(ctx, (self.driver, self.peer))
        wait_for(lambda: self.commands.get_subscription_count() > 0, what='discovery')
        self.closed = False

    def command_until(self, currents, board, pwm):
        """Publish until the emulator drives ``pwm`` (x+ x- y+ y-)."""
        deadline = time.monotonic() + TIMEOUT
        while fw(board, 'pwm').tolist() != list(pwm):
            assert time.monotonic() < deadline, f'command {currents} never reached the board'
            self.commands.publish(command_message(0, [float(c) for c in currents]))
            time.sleep(0.02)

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
def make_harness(ctx):
    made = []

    def make(port, **params):
        made.append(Harness(ctx, port, **params))
        return made[-1]

    yield make
    for harness in made:
        harness.close()


def stamp_ns(msg):
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def test_fields_and_currents_reach_ros_in_si_units_and_our_order(board, make_harness):
    h = make_harness(board.path, start_enabled=True, command_timeout=1.0)
    # 1 A on x+ (-1 A on x-), -2 A on y+ (2 A on y-): p_x = 85, p_y = -170
    h.command_until([1.0, -1.0, -2.0, 2.0], board, [85, -85, -170, 170])
    expected = adc_current(np.array([1.0, -1.0, -2.0, 2.0])).astype(float)  # x+ x- y+ y-
    wait_for(
        lambda: sum(list(m.effort) == expected.tolist() for m in list(h.currents)) > 200,
        timeout=TIMEOUT,
        what='measured currents',
    )
    now = time.time_ns()
    currents = list(h.currents)
    assert currents[-1].name == ['x+', 'x-', 'y+', 'y-']
    assert len(set(expected.tolist())) == 4  # a swapped coil would show
    stamps = np.array([stamp_ns(m) for m in currents])
    assert np.all(np.diff(stamps) > 0)
    assert abs(stamps[-1] - now) < 2e9  # host clock
    # the fields: exactly the board's sensor replies, mT -> T, x y z (the fields
    # taken first: each one then came from a reply the board had sent)
    received = list(h.fields)
    with board.lock:
        replies = [r for r in board.firmware.replies if r[0] == proto.READ_SENSORS]
    sent = {
        tuple(np.array(proto.decode_reply(r, proto.READ_SENSORS).field_mT) * 1e-3)
        for r in replies[-5000:]
    }
    stepped = [stamp_ns(m) for m in currents if list(m.effort) == expected.tolist()]
    fields = [m for m in received if stamp_ns(m) >= stepped[0]]
    assert len(fields) > 200
    assert fields[-1].header.frame_id == 'maglev_sensor_0'
    # the newest (the replies kept above are the board's last 5000)
    got = [(m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z) for m in fields[-1000:]]
    assert all(g in sent for g in got)
    # once the board's filters settled after the command: the step, in T, x y z
    # (feedthrough removal leaves < 0.1 mT); the samples before the command, or in
    # the filters' transient, are as many as the load made them
    np.testing.assert_allclose(np.mean(got[-50:], axis=0), STEP * 1e-3, atol=0.1e-3)
    # one field and one currents message per sample, with the same stamp
    wait_for(
        lambda: set(stamps.tolist()) <= {stamp_ns(m) for m in list(h.fields)},
        timeout=TIMEOUT,
        what='a field for every currents message',
    )
    h.diagnostics.clear()
    wait_for(lambda: len(h.diagnostics) > 0, timeout=TIMEOUT, what='diagnostics')
    values = {kv.key: kv.value for kv in h.diagnostics[-1].status[0].values}
    assert values['field kind'].startswith('processed, in T')
    assert values['firmware'] == 'v4x_pc'
    assert float(values['command latency p50 (ms)']) > 0


def test_pair_command_is_clamped_and_reaches_the_wire(board, make_harness):
    h = make_harness(board.path, start_enabled=True, command_timeout=1.0, current_limit=2.0)
    h.command_until([0.5, 0.1, 0.0, 0.0], board, [17, -17, 0, 0])  # (0.5 - 0.1) / 2 A
    h.command_until([9.0, -9.0, -0.1, 0.1], board, [170, -170, -8, 8])  # clamped to 2 A
    assert h.driver.counters['commands_clamped'] >= 1


def test_command_timeout_resets_the_coils(board, make_harness):
    h = make_harness(board.path, start_enabled=True, command_timeout=0.1)
    h.command_until([1.0, -1.0, 0.5, -0.5], board, [85, -85, 42, -42])
    before = resets(board)
    assert board.wait_until(lambda b: b.firmware.pwm.tolist() == [0, 0, 0, 0], TIMEOUT)
    assert board.wait_until(lambda b: b.firmware.requests[proto.RESET] > before, TIMEOUT)
    assert h.driver.counters['timeouts'] >= 1


def test_disable_resets_the_coils(board, make_harness):
    h = make_harness(board.path, start_enabled=True, command_timeout=1.0)
    h.command_until([1.0, -1.0, 0.5, -0.5], board, [85, -85, 42, -42])
    before = resets(board)
    assert 'zero' in h.enable(False).message
    assert board.wait_until(lambda b: b.firmware.requests[proto.RESET] > before, TIMEOUT)
    assert fw(board, 'pwm').tolist() == [0, 0, 0, 0]
    for _ in range(10):  # disabled: commands give zero
        h.commands.publish(command_message(0, [1.0, -1.0, 0.5, -0.5]))
        time.sleep(0.02)
    assert fw(board, 'pwm').tolist() == [0, 0, 0, 0]


def test_link_error_resets_the_coils(board, make_harness):
    h = make_harness(board.path, start_enabled=True, command_timeout=1.0)
    h.command_until([1.0, -1.0, 0.5, -0.5], board, [85, -85, 42, -42])
    before = resets(board)
    board.inject(b'\x05garbage\x00')  # bytes no request asked for: a bad reply
    wait_for(lambda: h.driver.counters['io_errors'] >= 1, timeout=TIMEOUT, what='the error')
    assert board.wait_until(lambda b: b.firmware.requests[proto.RESET] > before, TIMEOUT)
    n = h.driver.counters['records']
    wait_for(lambda: h.driver.counters['records'] > n + 50, timeout=TIMEOUT, what='samples')
    assert fw(board, 'pwm').tolist() == [0, 0, 0, 0]  # the old command is not re-applied
    assert h.driver.link_state == 'connected'
    h.command_until([1.0, -1.0, 0.5, -0.5], board, [85, -85, 42, -42])  # a new one is


def test_unplug_then_plug_resets_the_coils_first(ctx):
    factory = PoweredThroughUnplug()
    with VirtualBoard(factory) as board:
        assert board.wait_until(lambda b: b.firmware.running, TIMEOUT)
        h = Harness(  # not make_harness: the driver goes before the board
            ctx,
            board.path,
            start_enabled=True,
            command_timeout=1.0,
            reconnect_min_delay=0.05,
            reconnect_max_delay=0.2,
        )
        try:
            h.command_until([1.0, -1.0, 0.0, 0.0], board, [85, -85, 0, 0])
            board.unplug()
            wait_for(lambda: h.driver.link_state != 'connected', timeout=TIMEOUT)
            # the board keeps its PWM while unplugged (no watchdog): nothing reaches it
            assert factory.firmware.pwm.tolist() == [85, -85, 0, 0]
            before = factory.firmware.requests[proto.RESET]
            with board.lock:  # what the board applied up to the plug (its clock may not move)
                applied_before = len(factory.firmware.applied)
            board.plug()
            wait_for(lambda: h.driver.counters['reconnects'] == 1, timeout=TIMEOUT)
            assert board.wait_until(lambda b: b.firmware.requests[proto.RESET] > before, TIMEOUT)
            with board.lock:
                after_plug = list(factory.firmware.applied)[applied_before:]
                assert after_plug[0][1:] == (0, 0)  # the reset came before any command
                assert factory.firmware.pwm.tolist() == [0, 0, 0, 0]
            assert factory.plugs == 2
        finally:
            h.close()


def _driver_process(port, domain, *extra):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    cmd = [sys.executable, '-m', 'maglev_ros.nodes.driver', '--ros-args', '-p', f'port:={port}']
    for item in extra:
        cmd += ['-p', item]
    return subprocess.Popen(
        cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_signal_resets_the_coils(ctx, domain, board, signum):
    proc = _driver_process(
        board.path, domain, 'firmware:=v4x_pc', 'start_enabled:=true', 'command_timeout:=1.0'
    )
    try:
        peer = rclpy.create_node('driver_v4x_pc_signal_peer', context=ctx)
        pub = peer.create_publisher(JointState, 'maglev/currents/command', 10)
        deadline = time.monotonic() + 30.0
        while fw(board, 'pwm').tolist() != [51, -51, -17, 17]:
            assert time.monotonic() < deadline, 'the driver process never applied a command'
            assert proc.poll() is None, proc.stdout.read()
            pub.publish(command_message(0, [0.6, -0.6, -0.2, 0.2]))
            time.sleep(0.05)
        before = resets(board)
        proc.send_signal(signum)  # the command keeps coming: only the shutdown zeroes
        while proc.poll() is None:
            pub.publish(command_message(0, [0.6, -0.6, -0.2, 0.2]))
            time.sleep(0.01)
            assert time.monotonic() < deadline + 15.0
        output = proc.stdout.read()
        assert proc.returncode == 0, output
        assert not re.findall(r'.*(?:\[ERROR\]|\[FATAL\]|Traceback).*', output), output
        assert resets(board) > before
        assert fw(board, 'pwm').tolist() == [0, 0, 0, 0]
        peer.destroy_node()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _one_line_exit_2(proc):
    out, _ = proc.communicate(timeout=60.0)
    lines = out.strip().splitlines()
    assert proc.returncode == 2, out
    assert len(lines) == 1, out
    return lines[0]


def test_unknown_firmware_exits_2(domain):
    line = _one_line_exit_2(_driver_process('/dev/null', domain, 'firmware:=v4x_pcx'))
    assert "firmware must be 'v2x', 'v4x' or 'v4x_pc' (V4x PC control), got 'v4x_pcx'" in line


def test_a_port_that_is_not_a_board_exits_2(domain, tmp_path):
    path = tmp_path / 'not_a_board'
    path.write_text('hello')
    line = _one_line_exit_2(_driver_process(str(path), domain, 'firmware:=v4x_pc'))
    assert f'cannot open {path}' in line and '(parameters port, firmware)' in line


def test_no_answer_to_the_ping_exits_2(domain):
    plant = LinearPlant.default(1)
    with VirtualBoard(partial(V2xFirmware, plant, 1, startup_delay=0.2)) as v2x:  # wrong board
        line = _one_line_exit_2(_driver_process(v2x.path, domain, 'firmware:=v4x_pc'))
    assert f'{v2x.path}: no answer to the ping (AA -> EE)' in line
    assert 'V4x PC-control firmware' in line


def test_node_raises_board_not_found(ctx, tmp_path):
    path = tmp_path / 'nothing'
    with pytest.raises(BoardNotFoundError, match=f'cannot open {path}'):
        DriverNode(
            context=ctx,
            parameter_overrides=[
                Parameter('port', value=str(path)),
                Parameter('firmware', value='v4x_pc'),
            ],
        )
