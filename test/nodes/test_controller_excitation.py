"""The controller node's excitation: added to the command, published apart, as the core adds it.

Simulator (lockstep, V2, magnet free, 0.1 mT noise, 0.098 mT steps, one sample
of sensor delay, coil dynamics), estimator and controller (``delay_commands``)
on one executor, a PRBS of 0.1 A on both pairs from 0.1 s. Every published
excitation must be the core's :class:`ExcitationSchedule` value of its sample,
the commands and true states those of :class:`ClosedLoop` run with the same
excitation (the same numbers), one command and one excitation per sample, and
the magnet within 0.5 mm of its set-point while excited.
"""

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from waiting import wait_for

from maglev_ros import topics
from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.control.excitation import CommandExcitation, ExcitationSchedule
from maglev_ros.nodes.controller import ControllerNode, ControllerParameterError, build_config
from maglev_ros.nodes.estimator import EstimatorNode
from maglev_ros.nodes.qos import LOCKSTEP_COMMAND_QOS, SENSOR_QOS
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.nodes.simulator import SimulatorNode
from maglev_ros.nodes.state_messages import odometry_state

RATE = 5000.0
SEED = 7
SAMPLES = 1500  # 0.3 s: 0.1 s of hold, then 0.2 s (1000 samples) of excitation
EXCITATION = CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs', seed=4, length=25000, start=0.1)


def params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def test_excitation_parameters_are_checked():
    cfg = build_config({'excitation_signal': 'chirp', 'excitation_band': [0.01, 0.1]})
    assert cfg.excitation == CommandExcitation('chirp', band=(0.01, 0.1))
    assert build_config({}).excitation == CommandExcitation()  # off by default
    for values, match in (
        ({'excitation_signal': 'noise'}, 'excitation_signal'),
        ({'excitation_band': [0.5, 0.1]}, 'excitation_band must be (low, high)'),
        ({'excitation_amplitude': -1.0}, 'excitation_amplitude'),
    ):
        try:
            build_config(values)
        except ControllerParameterError as err:
            assert match in str(err), err
        else:
            raise AssertionError(f'{values} accepted')


def test_the_excitation_is_added_and_published_as_the_core_adds_it(ctx):
    loop = make_closed_loop('maggy_v2', noise=1e-4, quantization=0.098e-3, seed=SEED)
    x0 = loop.simulator.model.hover_state(loop.z_eq)
    sim = SimulatorNode(
        context=ctx,
        parameter_overrides=params(
            params='maggy_v2',
            mode='lockstep',
            magnet='free',
            sensor_noise=1e-4,
            sensor_quantization=0.098e-3,
            sensor_delay=1,
            seed=SEED,
            initial_state=[float(v) for v in x0],
            start_paused=True,
            marker_rate=0.0,
            command_timeout=120.0,  # the first sample compiles
        ),
    )
    est = EstimatorNode(context=ctx)
    e = EXCITATION
    ctrl = ControllerNode(
        context=ctx,
        parameter_overrides=params(
            delay_commands=True,
            excitation_signal=e.signal,
            excitation_amplitude=e.amplitude,
            excitation_band=list(e.band),
            excitation_pattern=e.pattern,
            excitation_seed=e.seed,
            excitation_length=e.length,
            excitation_start=e.start,
        ),
    )
    import rclpy

    peer = rclpy.create_node('excitation_test_peer', context=ctx)
    true, commands, excitations = {}, [], []
    subscriptions = []
    subscriptions.append(
        peer.create_subscription(
            Odometry,
            topics.TRUE_STATE_TOPIC,
            lambda m: true.__setitem__(
                m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, odometry_state(m)
            ),
            SENSOR_QOS,
        )
    )
    for topic, received in (
        (topics.COMMAND_TOPIC, commands),
        (topics.EXCITATION_TOPIC, excitations),
    ):
        subscriptions.append(
            peer.create_subscription(
                JointState,
                topic,
                lambda m, received=received: received.append(list(m.effort)),
                LOCKSTEP_COMMAND_QOS,
            )
        )
    spinner = Spinner(ctx, [sim, est, ctrl, peer])
    try:
        wait_for(lambda: sim.currents_subscribers >= 2, what='discovery')
        wait_for(lambda: ctrl._pub.get_subscription_count() >= 2, what='command discovery')
        wait_for(
            lambda: ctrl._excitation_pub.get_subscription_count() >= 1,
            what='excitation discovery',
        )
        # discovery is matched from each side separately: the peer hears every message
        wait_for(
            lambda: all(sub.get_publisher_count() >= 1 for sub in subscriptions),
            what="the peer's discovery",
        )
        sim.set_paused(False)
        wait_for(
            lambda: len(true) >= SAMPLES and len(commands) >= SAMPLES,
            timeout=240.0,
            what=f'{SAMPLES} samples',
        )
    finally:
        sim.set_paused(True)
        spinner.close()
    n = SAMPLES
    # one excitation per command, in the same order (each just before its command: the
    # spinner may stop between the two)
    assert len(excitations) - len(commands) in (0, 1), (len(excitations), len(commands))
    published = np.array(excitations[:n])
    # the core's value of each sample; delay_commands publishes sample k's at k + 1
    expected = ExcitationSchedule(EXCITATION, RATE).sequence(n)
    np.testing.assert_array_equal(published[0], np.zeros(4))
    np.testing.assert_array_equal(published[1:], expected[: n - 1])
    assert np.count_nonzero(published[:, 0]) > 900  # excited from 0.1 s on
    # the ROS-free loop with the same excitation: the same numbers
    ref = loop.run(n / RATE, x0=x0, excitation=expected)
    stamps = sorted(true)[:n]
    x = np.array([true[s] for s in stamps])
    np.testing.assert_allclose(x, ref.x[:n], rtol=0, atol=1e-12)
    total = np.array(commands[1:n])
    np.testing.assert_allclose(total, ref.command[: n - 1] + expected[: n - 1], rtol=0, atol=1e-12)
    # the magnet within 0.5 mm of its set-point while excited
    error = x[int(0.1 * RATE) :, :3] - np.array([0.0, 0.0, loop.z_eq])
    excursion = np.abs(error).max()
    assert excursion < 0.5e-3, excursion
    assert ctrl.controller.status().level == 'OK'
