import os
import signal
import subprocess
import sys
import time
from collections import deque

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, MagneticField
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray
from waiting import wait_for

from maglev_ros.cdr import odometry_layout
from maglev_ros.cdr.batch import RawMessageBatch
from maglev_ros.cdr.typestore import jazzy_typestore
from maglev_ros.nodes import contract
from maglev_ros.nodes.messages import command_message
from maglev_ros.nodes.simulator import (
    SimulatorNode,
    SimulatorParameterError,
    build_config,
    make_simulator,
)
from maglev_ros.physics import Simulator

TIMEOUT = 30.0  # s, generous: the machine is shared


class Peer:
    """The simulator and a test peer on one executor; the peer answers each sample."""

    def __init__(self, ctx, commands=None, lockstep=True, raw=False, streams=None, **params):
        params.setdefault('mode', 'lockstep' if lockstep else 'realtime')
        params.setdefault('start_paused', True)
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        self.sim = SimulatorNode(context=ctx, parameter_overrides=overrides)
        self.node = rclpy.create_node('simulator_test_peer', context=ctx)
        self.commands = None if commands is None else np.asarray(commands, dtype=float)
        self.sent = 0
        self.fields = {k: [] for k in self.sim.sensors}
        self.currents, self.states, self.clock = [], [], []
        self.diagnostics = deque(maxlen=20)
        self.markers = deque(maxlen=2)
        # the product's sensor QoS with a deeper reader queue: on a loaded machine this
        # peer's one executor falls seconds behind 5 kHz real time, and a test of the
        # simulator must not count the samples such a slow reader drops
        qos = QoSProfile(
            depth=50_000,
            reliability=contract.SENSOR_QOS.reliability,
            history=contract.SENSOR_QOS.history,
        )
        self.pub = self.node.create_publisher(
            JointState, contract.COMMAND_TOPIC, contract.LOCKSTEP_COMMAND_QOS
        )
        # streams: the 5 kHz streams besides the currents this peer takes (all by
        # default); each costs the shared executor ~130 us a sample
        streams = ('fields', 'state', 'clock') if streams is None else streams
        for k in self.sim.sensors if 'fields' in streams else ():
            self.node.create_subscription(
                MagneticField, contract.field_topic(k), self.fields[k].append, qos, raw=raw
            )
        if 'state' in streams:
            self.node.create_subscription(
                Odometry, contract.TRUE_STATE_TOPIC, self.states.append, qos, raw=raw
            )
        self._per_sample = [self.currents]  # the streams with one message a sample
        self._per_sample += list(self.fields.values()) if 'fields' in streams else []
        self._per_sample += [self.states] if 'state' in streams else []
        if 'clock' in streams:
            self.node.create_subscription(
                Clock, contract.CLOCK_TOPIC, self.clock.append, qos, raw=raw
            )
        self.node.create_subscription(
            JointState, contract.CURRENTS_TOPIC, self._on_sample, qos, raw=raw
        )
        self.node.create_subscription(
            DiagnosticArray, '/diagnostics', lambda m: self.diagnostics.append(m), 10
        )
        self.node.create_subscription(
            MarkerArray,
            contract.MARKERS_TOPIC,
            lambda m: self.markers.append(m),
            contract.MARKERS_QOS,
        )
        self.reset_client = self.node.create_client(Trigger, 'maglev/simulator/reset')
        self.pause_client = self.node.create_client(SetBool, 'maglev/simulator/pause')
        self.closed = False
        self.spinner = contract.Spinner(ctx, [self.sim, self.node])
        wait_for(
            lambda: (
                self.pub.get_subscription_count() > 0
                and self.sim.command_publishers > 0
                and self.sim.currents_subscribers > 0
            ),
            what='discovery',
        )

    def _on_sample(self, msg):
        self.currents.append(msg)
        if self.commands is not None and self.sent < len(self.commands):
            self.pub.publish(command_message(stamp_ns(msg), self.commands[self.sent]))
            self.sent += 1

    def drain(self, quiet=0.5):
        """Wait until no stream has grown for ``quiet`` s and all hold equally many."""
        streams = self._per_sample

        def counts():
            return tuple(len(s) for s in streams)

        last = [counts(), time.monotonic()]

        def settled():
            now = counts()
            if now != last[0]:
                last[:] = [now, time.monotonic()]
                return False
            return len(set(now)) == 1 and time.monotonic() - last[1] >= quiet

        wait_for(settled, timeout=2 * TIMEOUT, what='the streams to drain')

    def call(self, client, request):
        assert client.wait_for_service(timeout_sec=TIMEOUT)
        future = client.call_async(request)
        wait_for(future.done, what='service')
        return future.result()

    def run(self, n_samples):
        """Resume and wait until n_samples samples arrived."""
        self.call(self.pause_client, SetBool.Request(data=False))
        wait_for(lambda: len(self.currents) >= n_samples, what=f'{n_samples} samples')

    def close(self):
        if self.closed:
            return
        self.closed = True
        self.spinner.close()
        self.sim.destroy_node()
        self.node.destroy_node()


@pytest.fixture
def make_peer(ctx):
    made = []

    def make(*args, **kwargs):
        peer = Peer(ctx, *args, **kwargs)
        made.append(peer)
        return peer

    yield make
    for peer in made:
        peer.close()


def stamp_ns(msg):
    stamp = msg.clock if isinstance(msg, Clock) else msg.header.stamp
    return stamp.sec * 10**9 + stamp.nanosec


def test_published_fields_equal_the_core_h_of_the_same_state(make_peer):
    rng = np.random.default_rng(1)
    n = 300
    commands = rng.uniform(-0.3, 0.3, (n, 4))
    peer = make_peer(commands, coil_dynamics=False, sensor_delay=0, marker_rate=20.0)
    peer.run(n + 1)
    sim = peer.sim
    model = sim.sim.model
    reference = make_simulator(sim.config)  # the core, driven with the same commands
    for i in range(n + 1):
        x = reference.state
        current = reference.currents
        stamp = i * 200_000
        assert [stamp_ns(peer.fields[k][i]) for k in sim.sensors] == [stamp] * 3
        assert stamp_ns(peer.clock[i]) == stamp_ns(peer.currents[i]) == stamp
        h = model.measurement(x, current)
        for k in sim.sensors:
            msg = peer.fields[k][i]
            assert msg.header.frame_id == f'maglev_sensor_{k}'
            got = [msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z]
            np.testing.assert_allclose(got, h[3 * k : 3 * k + 3], rtol=1e-12, atol=1e-18)
        np.testing.assert_array_equal(peer.currents[i].effort, current)
        assert list(peer.currents[i].name) == ['x+', 'x-', 'y+', 'y-']
        odom = peer.states[i]
        assert (odom.header.frame_id, odom.child_frame_id) == ('maglev_base', 'maglev_magnet')
        assert odom.pose.pose.position.z == x[2]
        np.testing.assert_allclose(odom.pose.pose.position.x, x[0], atol=1e-15)
        if i < n:
            reference.step(commands[i])
    assert np.ptp([m.pose.pose.position.x for m in peer.states]) > 0  # the magnet moved
    assert sim.counters['timeouts'] == 0
    wait_for(lambda: len(peer.markers) > 0, what='markers')
    namespaces = [m.ns for m in peer.markers[-1].markers]
    assert namespaces.count('solenoids') == 4 and namespaces.count('magnet') == 1


def test_true_state_as_odometry():
    x = np.array([0.001, -0.002, 0.03, 0.1, -0.2, 0.3, 0.5, -0.4, 0.2, 1.0, 2.0, 3.0])
    msg = contract.odometry_message(123, x)
    q = msg.pose.pose.orientation
    a, b, g = x[3:6]

    def rot(axis, angle):
        c, s = np.cos(angle), np.sin(angle)
        i, j = [(1, 2), (0, 2), (0, 1)][axis]
        m = np.eye(3)
        m[i, i] = m[j, j] = c
        m[i, j], m[j, i] = (-s, s) if axis != 1 else (s, -s)
        return m

    R = rot(2, g) @ rot(1, b) @ rot(0, a)
    w, v = q.w, np.array([q.x, q.y, q.z])
    Rq = (
        (w * w - v @ v) * np.eye(3)
        + 2 * np.outer(v, v)
        + 2 * w * np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    )
    np.testing.assert_allclose(Rq, R, atol=1e-14)
    twist = msg.twist.twist
    np.testing.assert_allclose(
        [twist.linear.x, twist.linear.y, twist.linear.z], R.T @ x[6:9], atol=1e-14
    )
    assert [twist.angular.x, twist.angular.y, twist.angular.z] == [1.0, 2.0, 3.0]
    layout = odometry_layout(contract.BASE_FRAME, contract.MAGNET_FRAME)
    (raw,) = RawMessageBatch(layout).serialise(np.array([123]), contract.odometry_values(x)[None])
    # byte for byte against an independent serialiser: rosbags writes canonical CDR (zero
    # padding); rclpy's serialize_message leaves its padding bytes uninitialised, so its
    # bytes differ from run to run and only its length is compared
    store = jazzy_typestore()
    canonical = store.serialize_cdr(
        store.deserialize_cdr(raw, 'nav_msgs/msg/Odometry'), 'nav_msgs/msg/Odometry'
    )
    assert raw == bytes(canonical)
    assert len(raw) <= len(serialize_message(msg))
    assert deserialize_message(raw, Odometry) == msg


def _lockstep_run(make_peer, seed, n=400):
    commands = np.random.default_rng(5).uniform(-1.0, 1.0, (n, 4))
    peer = make_peer(
        commands,
        seed=seed,
        sensor_noise=2e-5,
        sensor_delay=1,
        coil_dynamics=True,
        magnet='fixed',
        marker_rate=0.0,
    )
    peer.run(n + 1)
    fields = np.array(
        [
            [stamp_ns(m), m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z]
            for k in peer.sim.sensors
            for m in peer.fields[k][: n + 1]
        ]
    )
    currents = np.array([[stamp_ns(m), *m.effort] for m in peer.currents[: n + 1]])
    states = np.array(
        [[m.pose.pose.position.z, m.twist.twist.linear.z] for m in peer.states[: n + 1]]
    )
    assert peer.sim.counters['timeouts'] == 0
    peer.close()
    return fields.tobytes(), currents.tobytes(), states.tobytes()  # bit patterns


def test_lockstep_is_bit_for_bit_reproducible(make_peer):
    first = _lockstep_run(make_peer, seed=7)
    second = _lockstep_run(make_peer, seed=7)
    other = _lockstep_run(make_peer, seed=8)
    assert first == second
    assert first[1] == other[1] and first[0] != other[0]  # same currents, other noise
    efforts = np.frombuffer(first[1]).reshape(-1, 5)[:, 1]
    assert efforts[0] == 0.0 and 0 < np.abs(efforts).max() < 1.0  # the L/R coil lags


def test_crash_is_reported_and_reset_recovers(make_peer):
    x0 = [0.001, 0.0, 0.0365] + [0.0] * 9
    peer = make_peer(
        np.zeros((100000, 4)),
        initial_state=x0,
        diagnostics_period=0.2,
        publish_state=True,
        marker_rate=0.0,
    )
    peer.run(1)
    sim = peer.sim

    def crashed():
        return any(
            s.level == DiagnosticStatus.ERROR and 'crashed' in s.message
            for d in list(peer.diagnostics)
            for s in d.status
        )

    wait_for(crashed, what='the crash on /diagnostics')
    status = next(
        s for d in list(peer.diagnostics) for s in d.status if s.level == DiagnosticStatus.ERROR
    )
    values = {kv.key: kv.value for kv in status.values}
    assert values['crash reason'] == 'touched the base'
    assert 0.05 < float(values['crash time (s)']) < 1.0
    assert sim.counters['crashes'] == 1
    time.sleep(0.5)  # let samples still in flight arrive
    before = len(peer.currents)
    time.sleep(0.5)
    assert len(peer.currents) == before  # integration stopped
    response = peer.call(peer.reset_client, Trigger.Request())
    assert response.success
    wait_for(lambda: len(peer.currents) > before + 50, what='samples after the reset')
    stamps = [stamp_ns(m) for m in peer.currents]
    assert np.all(np.diff(stamps) > 0)  # time continues across the reset
    assert sim.counters['resets'] == 1
    first = next(m for m in peer.states if stamp_ns(m) == stamps[before])
    assert first.pose.pose.position.x == pytest.approx(0.001)  # back at the initial state
    assert stamps[before] == stamps[before - 1] + 200_000


def euler_of(q):
    """ZYX Euler angles (alpha, beta, gamma) of a geometry_msgs Quaternion."""
    w, x, y, z = q.w, q.x, q.y, q.z
    return (
        np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
        np.arcsin(2 * (w * y - z * x)),
        np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)),
    )


def test_realtime_bursts_publish_the_core_h_until_the_crash(make_peer):
    # real time steps and publishes in bursts (1 ms, 5 samples): every sample of the
    # free, falling magnet arrives, its fields are h(x, i) of its own published state,
    # /clock comes once per burst, and the burst that crashes publishes up to the crash
    x0 = [0.001, 0.0, 0.0365] + [0.0] * 9
    peer = make_peer(
        lockstep=False,
        initial_state=x0,
        coil_dynamics=False,
        sensor_delay=0,
        marker_rate=0.0,
        diagnostics_period=0.2,
    )
    sim = peer.sim
    peer.call(peer.pause_client, SetBool.Request(data=False))
    wait_for(lambda: sim.counters['crashes'] == 1, what='the crash')
    peer.drain()  # samples in flight: on a loaded machine seconds of them
    n = len(peer.currents)
    stamps = np.array([stamp_ns(m) for m in peer.currents])
    assert n > 100 and np.all(np.diff(stamps) == 200_000)  # none lost, none repeated
    assert stamps[-1] < sim.sim.crash_time * 1e9
    by_stamp = {k: {stamp_ns(m): m for m in peer.fields[k]} for k in sim.sensors}
    states = {stamp_ns(m): m for m in peer.states}
    model = sim.sim.model
    for msg in peer.currents:
        t_ns = stamp_ns(msg)
        pose = states[t_ns].pose.pose
        x = np.zeros(12)
        x[0:3] = pose.position.x, pose.position.y, pose.position.z
        x[3:6] = euler_of(pose.orientation)
        h = model.measurement(x, np.array(msg.effort))
        for j, k in enumerate(sim.sensors):
            field = by_stamp[k][t_ns].magnetic_field
            np.testing.assert_allclose(
                [field.x, field.y, field.z], h[3 * j : 3 * j + 3], rtol=1e-9, atol=1e-15
            )
    assert np.ptp([states[t].pose.pose.position.x for t in stamps]) > 1e-4  # it moved
    clock = np.array([stamp_ns(m) for m in peer.clock])
    clock = clock[(clock >= stamps[0]) & (clock <= stamps[-1])]
    np.testing.assert_array_equal(clock, stamps[stamps % 1_000_000 == 0])  # one per burst


def test_realtime_averaged_samples_are_means_of_five_steps_on_the_1_khz_grid(make_peer):
    # average 5 at 5 kHz: one sample per 1 ms burst, stamped at its group's last step,
    # its fields the mean of the group's 5 readings (the core's own steps, bit for bit
    # up to the mean's round-off), /clock with each sample (one per burst)
    x0 = [0.001, 0.0, 0.0365] + [0.0] * 9
    peer = make_peer(
        lockstep=False, initial_state=x0, coil_dynamics=False, sensor_delay=0, marker_rate=0.0,
        diagnostics_period=0.2, average=5,
    )  # fmt: skip
    sim = peer.sim
    peer.call(peer.pause_client, SetBool.Request(data=False))
    wait_for(lambda: sim.counters['crashes'] == 1, what='the crash')
    peer.drain()
    stamps = np.array([stamp_ns(m) for m in peer.currents])
    assert len(stamps) > 20 and np.all(np.diff(stamps) == 1_000_000), stamps[:5]
    reference = Simulator(sim.sim.model, 5000.0, x0=x0)
    readings = [reference.reset()] + [reference.step(np.zeros(4)) for _ in range(5 * 20)]
    means = [readings[0]] + [np.mean(readings[5 * m - 4 : 5 * m + 1], axis=0)
                             for m in range(1, 21)]  # fmt: skip
    by_stamp = {stamp_ns(m): m for m in peer.fields[sim.sensors[0]]}
    compared = [m for m in range(21) if m * 1_000_000 in by_stamp]
    assert len(compared) >= 15, sorted(by_stamp)[:5]  # the first may precede the subscription
    for m in compared:
        field = by_stamp[m * 1_000_000].magnetic_field
        np.testing.assert_allclose([field.x, field.y, field.z], means[m][:3], rtol=1e-12,
                                   atol=1e-15)  # fmt: skip
    clock = np.array([stamp_ns(m) for m in peer.clock])
    np.testing.assert_array_equal(clock[(clock >= stamps[0]) & (clock <= stamps[-1])], stamps)


def test_the_run_starts_once_the_start_reader_reads_the_commands(ctx, make_peer):
    """A recorder named as ``start_reader`` holds the start until it subscribes."""
    peer = make_peer([[0.1, 0.0, 0.0, 0.0]] * 50, start_paused=False, magnet='fixed',
                     marker_rate=0.0, start_reader='maglev_test_recorder')  # fmt: skip
    assert (
        'and for maglev_test_recorder to read maglev/currents/command'
        in peer.sim.config.summary('maggy_v2', peer.sim.sensors)
    )
    # a command publisher and a currents reader are there (the peer): only the reader misses;
    # the start is checked every 0.05 s, and ten checks pass without a sample
    time.sleep(0.5)
    assert peer.currents == []
    recorder = rclpy.create_node('maglev_test_recorder', context=ctx)
    try:
        recorder.create_subscription(
            JointState, contract.COMMAND_TOPIC, lambda m: None, contract.LOCKSTEP_COMMAND_QOS
        )
        wait_for(lambda: len(peer.currents) >= 20, what='samples after the reader subscribed')
    finally:
        recorder.destroy_node()


def test_averaged_samples_in_lockstep_are_refused(ctx):
    with pytest.raises(SimulatorParameterError, match='average 5 .* needs mode realtime'):
        SimulatorNode(context=ctx, parameter_overrides=[
            Parameter('average', value=5), Parameter('mode', value='lockstep')])  # fmt: skip


def test_lockstep_timeout_holds_the_last_command(make_peer):
    peer = make_peer(
        [[0.2, 0.0, 0.0, 0.0]], coil_dynamics=False, command_timeout=0.1, marker_rate=0.0
    )
    peer.run(4)
    assert peer.sim.counters['timeouts'] >= 2
    assert list(peer.currents[3].effort) == [0.2, 0.0, 0.0, 0.0]


def test_realtime_follows_commands_and_pauses(make_peer):
    peer = make_peer(
        lockstep=False,
        coil_dynamics=False,
        marker_rate=0.0,
        start_paused=False,
        magnet='fixed',
        sensors=[0],
        publish_clock=False,
        publish_state=False,
        diagnostics_period=0.5,
        streams=(),  # only the currents: on a loaded machine the executor keeps up
    )
    wait_for(lambda: len(peer.currents) > 500, what='real-time samples')
    wait_for(
        lambda: (
            any(list(m.effort) == [0.5, -0.5, 0.0, 0.0] for m in peer.currents[-50:])
            or peer.pub.publish(
                command_message(stamp_ns(peer.currents[-1]), [0.5, -0.5, 0.0, 0.0])
            )
        ),
        what='the command applied',
    )
    stamps = np.array([stamp_ns(m) for m in peer.currents])
    assert np.all(np.diff(stamps) > 0) and np.all(stamps % 200_000 == 0)
    peer.call(peer.pause_client, SetBool.Request(data=True))
    time.sleep(0.5)  # samples in flight
    count = len(peer.currents)
    time.sleep(0.5)
    assert len(peer.currents) == count
    peer.call(peer.pause_client, SetBool.Request(data=False))
    wait_for(lambda: len(peer.currents) > count + 100, what='samples after resume')
    wait_for(
        lambda: any(
            float(kv.value) > 0
            for d in list(peer.diagnostics)
            for s in d.status
            for kv in s.values
            if kv.key == 'real-time factor'
        ),
        timeout=2 * TIMEOUT,  # a loaded machine runs the simulator far slower than 1.0
        what='a real-time factor',
    )
    for key in ('late commands', 'held samples', 'overruns'):
        assert any(kv.key == key for kv in peer.diagnostics[-1].status[0].values)


def _values(**changes):
    values = {
        'params': 'maggy_v2',
        'field_model': 'fast',
        'torque': 'true',
        'kinematics': 'rigid',
        'sample_rate': 5000.0,
        'substeps': 1,
        'magnet': 'free',
        'initial_state': None,
        'coil_dynamics': True,
        'sensor_noise': 0.0,
        'sensor_quantization': 0.0,
        'sensor_delay': 1,
        'seed': 0,
        'mode': 'realtime',
        'command_timeout': 1.0,
        'pace_period': 0.001,
        'start_paused': False,
        'start_subscribers': 0,
        'sensors': None,
        'publish_state': True,
        'publish_clock': True,
        'marker_rate': 10.0,
        'diagnostics_period': 1.0,
    }
    return values | changes


@pytest.mark.parametrize(
    'changes, match',
    [
        ({'mode': 'fast'}, "mode must be one of realtime, lockstep, got 'fast'"),
        ({'magnet': 'glued'}, "magnet must be one of free, fixed, absent, got 'glued'"),
        ({'sample_rate': 0.0}, 'sample_rate must be a finite number > 0, got 0.0'),
        ({'sensor_noise': -1.0}, 'sensor_noise must be a finite number >= 0'),
        ({'initial_state': [0.0] * 3}, 'initial_state must be 12 finite numbers'),
        ({'sensors': [0, 0]}, 'sensors must be distinct sensor indices'),
        ({'field_model': 'slow'}, 'field_model must be one of fast, accurate, filament'),
        ({'substeps': 0}, 'substeps must be an integer >= 1, got 0'),
        ({'seed': -3}, 'seed must be an integer >= 0, got -3'),
        ({'start_reader': '/ns/rec'}, "start_reader must be a node name .* got '/ns/rec'"),
        ({'start_reader_topics': ['a b']}, r"start_reader_topics must name topics, got \['a b'\]"),
    ],
)
def test_config_errors(changes, match):
    with pytest.raises(SimulatorParameterError, match=match):
        build_config(_values(**changes))


def test_unknown_parameter_set_and_sensor(ctx):
    with pytest.raises(SimulatorParameterError, match="params 'maggy_v9'"):
        make_simulator(build_config(_values(params='maggy_v9')))
    with pytest.raises(SimulatorParameterError, match='sensors must be indices below 3'):
        SimulatorNode(context=ctx, parameter_overrides=[Parameter('sensors', value=[5])])


def _process(domain, *params):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    cmd = [sys.executable, '-m', 'maglev_ros.nodes.simulator', '--ros-args']
    for item in params:
        cmd += ['-p', item]
    return subprocess.Popen(
        cmd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )


def test_main_exits_2_on_invalid_parameters(domain):
    proc = _process(domain, 'mode:=turbo')
    out, _ = proc.communicate(timeout=60.0)
    assert proc.returncode == 2
    assert "mode must be one of realtime, lockstep, got 'turbo'" in out
    assert 'Traceback' not in out


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_signal_ends_the_node_cleanly(ctx, domain, signum):
    proc = _process(domain, 'marker_rate:=0.0')
    try:
        node = rclpy.create_node('simulator_signal_peer', context=ctx)
        got = []
        node.create_subscription(
            JointState, contract.CURRENTS_TOPIC, got.append, contract.SENSOR_QOS
        )
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        deadline = time.monotonic() + 60.0
        while len(got) < 100:
            assert time.monotonic() < deadline and proc.poll() is None, 'no samples'
            executor.spin_once(timeout_sec=0.05)
        executor.shutdown()
        proc.send_signal(signum)
        out, _ = proc.communicate(timeout=30.0)
        assert proc.returncode == 0, out
        assert 'Traceback' not in out
        node.destroy_node()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_diagnostics_are_stamped_with_the_node_clock_under_sim_time(make_peer):
    """Issue 11 item 6: under use_sim_time the /diagnostics stamps are simulated time."""
    peer = make_peer(
        lockstep=False,
        magnet='fixed',
        diagnostics_period=0.1,
        marker_rate=0.0,
        use_sim_time=True,
    )
    peer.run(2000)
    wait_for(lambda: peer.sim.get_clock().now().nanoseconds > 0, what='sim time')
    peer.sim.publish_diagnostics()  # (the node's timer runs on sim time too)
    wait_for(lambda: len(peer.diagnostics) >= 1, what='diagnostics')
    stamps = [d.header.stamp.sec + d.header.stamp.nanosec * 1e-9 for d in list(peer.diagnostics)]

    def newest_clock() -> float:
        return max(c.clock.sec + c.clock.nanosec * 1e-9 for c in list(peer.clock))

    # the /clock messages may reach this peer after the diagnostics they stamped: wait
    # (a few seconds at most) until simulated time has passed every stamp; a wall-time
    # stamp (~1.8e9 s) is never reached
    try:
        wait_for(lambda: newest_clock() >= max(stamps) - 1e-9, timeout=5.0, what='sim time')
    except AssertionError:
        pass
    assert max(stamps) <= newest_clock() + 1e-9, (stamps, newest_clock())  # not wall time
    assert max(stamps) > 0.0
