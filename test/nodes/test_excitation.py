import os
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from waiting import wait_for

from maglev_ros.nodes import contract
from maglev_ros.nodes.excitation import (
    ExcitationNode,
    ExcitationParameterError,
    build_config,
    commands_of,
)
from maglev_ros.nodes.messages import stamp_ns
from maglev_ros.nodes.simulator import SimulatorNode

TIMEOUT = 30.0


def params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def test_excitation_drives_the_lockstep_simulator_sample_by_sample(ctx):
    excite = ExcitationNode(
        context=ctx,
        parameter_overrides=params(
            signal='prbs',
            amplitude=0.3,
            band=[0.0, 0.5],
            pattern='pairs',
            seed=4,
            length=200,
            cycles=1,
            offset=[0.0, 0.0, 0.05, 0.05],
        ),
    )
    sim = SimulatorNode(
        context=ctx,
        parameter_overrides=params(
            mode='lockstep',
            magnet='fixed',
            coil_dynamics=False,
            start_paused=True,
            marker_rate=0.0,
            sensors=[0],
        ),
    )
    peer = rclpy.create_node('excitation_test_peer', context=ctx)
    commands, currents, command_stamps, sample_stamps = [], [], [], []
    peer.create_subscription(
        JointState,
        contract.COMMAND_TOPIC,
        lambda m: commands.append(list(m.effort)) or command_stamps.append(stamp_ns(m)),
        contract.LOCKSTEP_COMMAND_QOS,
    )
    peer.create_subscription(
        JointState,
        contract.CURRENTS_TOPIC,
        lambda m: currents.append(list(m.effort)) or sample_stamps.append(stamp_ns(m)),
        contract.SENSOR_QOS,
    )
    spinner = contract.Spinner(ctx, [excite, sim, peer])
    try:
        wait_for(
            lambda: (
                excite.command_subscribers >= 2
                and sim.command_publishers >= 1
                and sim.currents_subscribers >= 2
            ),
            what='discovery',
        )
        sim.set_paused(False)
        wait_for(lambda: len(currents) > 260, what='samples')
        expected = commands_of(excite.config)
        np.testing.assert_array_equal(commands[:200], expected)
        assert commands[200:250] == [[0.0, 0.0, 0.05, 0.05]] * 50  # after the last cycle
        np.testing.assert_array_equal(currents[1:201], expected)  # command k -> sample k + 1
        assert expected[:, 0].tolist() == (-expected[:, 1]).tolist()  # antisymmetric pair
        assert sim.counters['timeouts'] == 0
        assert command_stamps[:250] == sample_stamps[:250]  # each stamped with its sample
        assert sim.session.command_lag == 0
    finally:
        spinner.close()
        for node in (excite, sim, peer):
            node.destroy_node()


def test_timer_trigger_publishes_at_its_rate(ctx):
    excite = ExcitationNode(
        context=ctx,
        parameter_overrides=params(
            signal='multisine', trigger='timer', sample_rate=200.0, length=64, band=[0.1, 0.4]
        ),
    )
    peer = rclpy.create_node('excitation_timer_peer', context=ctx)
    got, stamps = [], []
    peer.create_subscription(
        JointState,
        contract.COMMAND_TOPIC,
        lambda m: got.append(list(m.effort)) or stamps.append(stamp_ns(m)),
        contract.COMMAND_QOS,
    )
    spinner = contract.Spinner(ctx, [excite, peer])
    try:
        wait_for(lambda: len(got) > 20, what='timer commands')
        assert all(len(c) == 4 and c[0] == -c[1] for c in got)
        assert np.all(np.diff(stamps) > 0)  # stamped with the node clock's time
    finally:
        spinner.close()
        excite.destroy_node()
        peer.destroy_node()


@pytest.mark.parametrize(
    'changes, match',
    [
        ({'signal': 'noise'}, 'signal must be one of prbs, random_binary, multisine, chirp'),
        ({'band': [0.5, 0.2]}, r'band must be \[low, high\]'),
        ({'offset': [0.0]}, 'offset must be 4 finite currents'),
        ({'length': 0}, 'length must be an integer >= 1, got 0'),
        ({'trigger': 'clock'}, "trigger must be one of sample, timer, got 'clock'"),
    ],
)
def test_config_errors(changes, match):
    values = {
        'signal': 'prbs',
        'amplitude': 0.5,
        'band': [0.0, 1.0],
        'pattern': 'pairs',
        'offset': [0.0] * 4,
        'seed': 0,
        'length': 100,
        'cycles': 0,
        'trigger': 'sample',
        'sample_rate': 5000.0,
    }
    with pytest.raises(ExcitationParameterError, match=match):
        build_config(values | changes)


def test_prbs_band_error_is_a_parameter_error(ctx):
    with pytest.raises(ExcitationParameterError, match='band of a prbs must start at 0'):
        ExcitationNode(context=ctx, parameter_overrides=params(band=[0.2, 0.5]))


def test_main_exits_2_on_invalid_parameters():
    proc = subprocess.run(
        [
            sys.executable,
            '-m',
            'maglev_ros.nodes.excitation',
            '--ros-args',
            '-p',
            'pattern:=diagonal',
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ, ROS_DOMAIN_ID='97', ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST'),
    )
    assert proc.returncode == 2
    assert 'pattern must be one of pairs' in proc.stdout + proc.stderr
    assert 'Traceback' not in proc.stdout + proc.stderr


def test_sigterm_ends_the_node_cleanly(ctx):
    import signal

    from rclpy.executors import SingleThreadedExecutor

    domain = os.environ['ROS_DOMAIN_ID']
    env = dict(os.environ, ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    proc = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'maglev_ros.nodes.excitation',
            '--ros-args',
            '-p',
            'trigger:=timer',
            '-p',
            'sample_rate:=100.0',
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        node = rclpy.create_node('excitation_signal_peer', context=ctx)
        got = []
        node.create_subscription(
            JointState, contract.COMMAND_TOPIC, got.append, contract.COMMAND_QOS
        )
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        deadline = time.monotonic() + 60.0
        while len(got) < 5:
            assert time.monotonic() < deadline and proc.poll() is None, 'no commands'
            executor.spin_once(timeout_sec=0.05)
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=30.0)
        assert proc.returncode == 0, out
        assert 'Traceback' not in out
        executor.shutdown()
        node.destroy_node()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_max_commands_stops_a_lockstep_simulation_after_exactly_that_many_steps(ctx):
    excite = ExcitationNode(
        context=ctx, parameter_overrides=params(length=100, max_commands=137, seed=2)
    )
    sim = SimulatorNode(
        context=ctx,
        parameter_overrides=params(
            mode='lockstep', magnet='fixed', start_paused=True, marker_rate=0.0, sensors=[0],
            command_timeout=30.0,
        ),
    )  # fmt: skip
    spinner = contract.Spinner(ctx, [excite, sim])
    try:
        wait_for(
            lambda: sim.currents_subscribers >= 1 and sim.command_publishers >= 1,
            what='discovery',
        )
        sim.set_paused(False)
        wait_for(lambda: excite.exhausted, what='the last command')
        time.sleep(0.5)  # nothing more comes: the simulator waits for a command
        assert excite.sent == 137 and sim.counters['samples'] == 138  # + the initial sample
    finally:
        spinner.close()
        excite.destroy_node()
        sim.destroy_node()
    with pytest.raises(ExcitationParameterError, match='max_commands must be an integer >= 0'):
        build_config({**excite.config.__dict__, 'band': [0.0, 1.0], 'offset': [0.0] * 4,
                      'max_commands': -1})  # fmt: skip
