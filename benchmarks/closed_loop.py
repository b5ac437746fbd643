"""The whole closed-loop graph in real time: real-time factor, sensor-to-command latency, CPU.

Issue 10, point 5, on the graph of ``maglev-lab --realtime``: the simulator
(``mode: realtime``, 5 kHz in bursts of 5 samples a millisecond, V2, magnet
free, coil dynamics, 0.1 mT noise, 0.098 mT steps, one sample of sensor
delay), the estimator (KF, an estimate per burst), the controller (LQR at
1 kHz, ``trigger: estimate``), the identifier (the main job's: x and y field
of sensor 0 against the pair commands, ARX 7 9 1 and 6 6 1) and the recorder
(the main job's topics, an MCAP bag in a temporary directory, deleted after),
in two layouts:

``composed``
    all five nodes in one process on the package's executor
    (:func:`maglev_ros.nodes.runtime.run_nodes`), as ``maglev-lab --realtime``
    composes them: samples, estimates and commands handed over in the
    simulator's thread, the identifier and the recorder on the publishers'
    taps (``intra_process``; the LQR designs for 1 ms of latency);
``separate``
    one process per node, ``python -m maglev_ros.nodes.<node> --ros-args -p ...``
    (what ``ros2 run`` starts; the LQR designs for 3 ms, as the launch file).

Measured by an observer node in this script's process (its own executor
thread; messages stored raw, with their arrival time), on ``/clock`` (one a
burst, stamped with its last sample: 1 kHz, so the observer costs the graph
little), the estimates and the commands:

* **real-time factor**: simulated time (the ``/clock`` stamps) over wall
  time, over ``--seconds``;
* **sensor-to-command latency**: for each command, from the arrival of the
  ``/clock`` of the burst it answers (published before the burst's samples)
  to the command's arrival. The controller answers each estimate once, in
  order: command j answers estimate j, whose stamp names the burst. Commands
  carry no stamp: the pairing is by count and is reported not valid when the
  counts differ (the controller skipped estimates);
* **the baseline, in the same run**: a bare rclpy ping-pong in the same
  layout and executor kind -- a pinger publishing stamped JointState
  messages at the simulator's ``sample_rate`` in 1 ms bursts, two echo nodes
  relaying each message (``bench/ping`` -> ``bench/echo`` -> ``bench/pong``,
  as samples -> estimate -> command) -- with the latency measured the same
  way (ping arrival to pong arrival, matched by stamp). Printed: the ratio of
  the loop's median and 99th percentile to the ping-pong's (target: within 2x);
* **CPU** of each process from ``/proc`` over the window, in % of one core;
  for the composed process also per thread (the simulator's stepping
  thread, the executor's, DDS's).

Node parameters can be overridden: ``--param NODE:NAME:=VALUE`` (NODE one of
simulator, estimator, controller, identifier, recorder; VALUE in YAML, as
``ros2 run ... -p``), e.g. ``--param controller:sample_rate:=1000.0``.

Usage::

    python benchmarks/closed_loop.py                       # 20 s per set-up
    python benchmarks/closed_loop.py --seconds 10 --only composed
    python benchmarks/closed_loop.py --param simulator:pace_period:=0.0005

Run it on a quiet machine: on a loaded 2-core machine the 5 kHz graph falls
behind real time.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from process_cpu import Processes, benchmark_environment, cpu_seconds, thread_cpu_seconds

from maglev_ros.cli.closed_loop_lab import IDENTIFIER_CHANNELS
from maglev_ros.topics import (
    CLOCK_TOPIC,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    TRUE_STATE_TOPIC,
    field_topic,
)

DOMAIN = 78  # ROS_DOMAIN_ID of the runs (localhost only)
NODES = ('simulator', 'estimator', 'controller', 'identifier', 'recorder')
GRAPH_PARAMETERS = {
    'simulator': {
        'params': 'maggy_v2',
        'magnet': 'free',
        'mode': 'realtime',
        'coil_dynamics': True,
        'sensor_delay': 1,
        'sensor_noise': 1e-4,
        'sensor_quantization': 0.098e-3,
        'seed': 0,
        'start_paused': True,  # resumed once every node has matched its topics
        'marker_rate': 0.0,
    },
    # the real-time pattern of closed_loop.launch.xml: control at 1 kHz, one estimate and
    # one command per 1 ms burst of samples
    'estimator': {
        'params': 'maggy_v2',
        'sensor_noise': 1e-4,
        'quantization': 0.098e-3,
        'publish_rate': 1000.0,
    },
    'controller': {
        'params': 'maggy_v2',
        'mode': 'lqr',
        'sample_rate': 1000.0,
        'trigger': 'estimate',
        'input_timeout': 0.02,
    },
    # the main job's identifier: x and y field of sensor 0 against the pair commands
    # (7 9 1 and 6 6 1), a sample per field message, a command answering it its input
    'identifier': {
        'outputs': list(IDENTIFIER_CHANNELS[0]),
        'inputs': list(IDENTIFIER_CHANNELS[1]),
        'na': [7, 0, 0, 6],
        'nb': [9, 0, 0, 6],
        'nk': [1, 1, 1, 1],
        'initial_covariance': 1e10,
        'trigger': field_topic(0),
        'complete_on_next': True,
        'publish_rate': 1.0,
    },
    # the main job's recording (path: a temporary directory)
    'recorder': {
        'storage': 'mcap',
        'topics': [field_topic(0), CURRENTS_TOPIC, COMMAND_TOPIC, TRUE_STATE_TOPIC, CLOCK_TOPIC],
    },
}
#: per layout: composed, samples, estimates and commands are handed over in the
#: simulator's thread and the identifier and the recorder take the topics from their
#: publishers' taps (intra_process; the LQR designs for 1 ms of latency): what
#: ``maglev-lab --realtime`` runs; separate, each passes the middleware (the launch
#: file's 3 ms design)
LAYOUT_PARAMETERS = {
    'composed': {
        'estimator': {'intra_process': True},
        'controller': {'intra_process': True, 'command_delay': 1},
        'identifier': {'intra_process': True},
        'recorder': {'intra_process': True, 'log_clock': 'stamp'},
    },
    'separate': {'controller': {'command_delay': 3}},
}
_PROFILE_ENV = 'CLOSED_LOOP_PROFILE'  # composed child: cProfile dump path
_TRACE_ENV = 'CLOSED_LOOP_TRACE'  # composed child: _LoopTrace file
PING, ECHO, PONG = 'bench/ping', 'bench/echo', 'bench/pong'
_PINGPONG = ('pinger', 'echo_1', 'echo_2')


class BenchmarkArgumentError(ValueError):
    """A command-line value is invalid."""


def parse_param(text: str) -> tuple[str, str, str]:
    """Split ``NODE:NAME:=VALUE``.

    Parameters
    ----------
    text : str
        The ``--param`` argument.

    Returns
    -------
    (node, name, value) : tuple of str

    Raises
    ------
    BenchmarkArgumentError
        If the form or the node is wrong.
    """
    head, sep, value = text.partition(':=')
    node, _, name = head.partition(':')
    if not sep or not name or node not in NODES:
        raise BenchmarkArgumentError(
            f'--param {text!r}: expected NODE:NAME:=VALUE with NODE one of {", ".join(NODES)}'
        )
    return node, name, value


def _yaml_text(value) -> str:
    """Return a Python parameter value as ``-p name:=VALUE`` text (YAML)."""
    return json.dumps(value) if not isinstance(value, str) else value


def graph_parameters(overrides: list[str], bag: str, layout: str) -> dict[str, dict]:
    """Return the graph's parameters with the ``--param`` overrides (values parsed as YAML).

    Parameters
    ----------
    overrides : list of str
        ``NODE:NAME:=VALUE`` texts.
    bag : str
        The recorder's bag path.
    layout : {'composed', 'separate'}
        Adds the layout's own parameters (:data:`LAYOUT_PARAMETERS`).
    """
    import yaml

    values = {node: dict(p) for node, p in GRAPH_PARAMETERS.items()}
    for node, extra in LAYOUT_PARAMETERS[layout].items():
        values[node].update(extra)
    values['recorder']['path'] = bag
    for text in overrides:
        node, name, value = parse_param(text)
        values[node][name] = yaml.safe_load(value)
    return values


# ---------------------------------------------------------------------- children
def _node_classes():
    from maglev_ros.nodes import controller, estimator, identifier, recorder, simulator

    errors = (
        simulator.SimulatorParameterError, estimator.EstimatorParameterError,
        controller.ControllerParameterError, identifier.IdentifierParameterError,
        recorder.RecorderParameterError,
    )  # fmt: skip
    classes = dict(
        simulator=simulator.SimulatorNode, estimator=estimator.EstimatorNode,
        controller=controller.ControllerNode, identifier=identifier.IdentifierNode,
        recorder=recorder.RecorderNode,
    )  # fmt: skip
    return classes, errors


class _LoopTrace:
    """Times ``/clock`` and the commands in the composed process, on their taps.

    Both are handed over in the simulator's thread, in order: a burst's
    ``/clock`` (stamped with its last sample) before its samples, its command
    after them; a command's burst is the latest ``/clock`` before it. No
    middleware is involved, so the measurement costs the graph about a
    microsecond a message (an observer subscribing in another process made
    every ``/clock`` and command cost the simulator's thread 25-75 us to
    publish).
    """

    def __init__(self) -> None:
        self.clock: list[tuple[int, int]] = []  # (monotonic ns, stamp ns)
        self.commands: list[int] = []  # monotonic ns
        self._unpack = struct.Struct('<iI').unpack_from
        self._taps = []

    def attach(self, context) -> None:
        """Listen to the ``/clock`` and command taps of ``context``'s nodes."""
        from maglev_ros.nodes import intra_process

        for topic, listener in ((CLOCK_TOPIC, self._on_clock), (COMMAND_TOPIC, self._on_command)):
            tap = intra_process.tap(context, '/' + topic.lstrip('/'))
            tap.connect(listener, 'closed_loop_trace')
            self._taps.append((tap, listener))

    def _on_clock(self, messages: list) -> None:
        now = time.monotonic_ns()
        for data in messages:
            sec, nanosec = self._unpack(data, 4)
            self.clock.append((now, sec * 1_000_000_000 + nanosec))

    def _on_command(self, messages: list) -> None:
        self.commands.append(time.monotonic_ns())

    def save(self, path: str) -> None:
        """Disconnect and write the times to ``path`` (``.npz``)."""
        for tap, listener in self._taps:
            tap.disconnect(listener)
        clock = np.array(self.clock, dtype=np.int64).reshape(-1, 2)
        np.savez(path, clock=clock, commands=np.array(self.commands, dtype=np.int64))


def composed_graph_child(values: dict[str, dict]) -> int:
    """Run the five graph nodes in this process on one executor until SIGINT.

    With ``CLOSED_LOOP_TRACE`` set, :class:`_LoopTrace` times the loop and
    writes its figures there at the end.

    Parameters
    ----------
    values : dict
        Node -> parameter name -> value.
    """
    from rclpy.parameter import Parameter

    from maglev_ros.nodes.runtime import run_nodes

    classes, errors = _node_classes()
    trace = _LoopTrace()

    def build(node):
        overrides = [Parameter(k, value=v) for k, v in values[node].items()]

        def make():
            made = classes[node](parameter_overrides=overrides)
            if node == 'identifier':  # the last: the simulator's and controller's taps exist
                trace.attach(made.context)
                import gc

                gc.freeze()
            return made

        return make

    # the recorder first: destroyed last, once the nodes writing to it are gone
    order = ['recorder', 'simulator', 'estimator', 'controller', 'identifier']
    factories = [build(n) for n in order]
    profile_path = os.environ.get(_PROFILE_ENV)
    trace_path = os.environ.get(_TRACE_ENV)
    try:
        if not profile_path:
            return run_nodes(factories, [sys.argv[0]], 'closed_loop', errors)
        import cProfile

        profiler = cProfile.Profile()  # the executor's (main) thread only
        try:
            return profiler.runcall(run_nodes, factories, [sys.argv[0]], 'closed_loop', errors)
        finally:
            profiler.dump_stats(profile_path)
    finally:
        if trace_path:
            trace.save(trace_path)


def traced_figures(path: Path, t0: int, t1: int) -> tuple[float, np.ndarray, int]:
    """Real-time factor and sensor-to-command latencies of a :class:`_LoopTrace` file.

    Parameters
    ----------
    path : Path
        The trace (``.npz``).
    t0, t1 : int
        The measured window, monotonic ns.

    Returns
    -------
    rtf : float
        Simulated over wall time of the bursts in the window.
    latency : ndarray of int
        ns from each command's burst (its ``/clock``) to the command, for the
        commands in the window.
    bursts : int
        Bursts in the window.
    """
    with np.load(path) as data:
        clock, commands = data['clock'], data['commands']
    inside = (clock[:, 0] >= t0) & (clock[:, 0] < t1)
    times, stamps = clock[inside, 0], clock[inside, 1]
    rtf = float(np.ptp(stamps) / max(np.ptp(times), 1)) if times.size > 1 else 0.0
    commands = commands[(commands >= t0) & (commands < t1)]
    burst = np.searchsorted(clock[:, 0], commands, side='right') - 1
    latency = commands[burst >= 0] - clock[burst[burst >= 0], 0]
    return rtf, latency, int(times.size)


def print_profile(path: Path, top: int = 12) -> None:
    """Print the executor thread's time per node callback and the top functions by own time.

    Parameters
    ----------
    path : Path
        A ``cProfile`` dump of the composed graph.
    top : int
        Functions listed.
    """
    import pstats

    stats = pstats.Stats(str(path))
    total = stats.total_tt
    print(
        f'    profile of the executor thread (cProfile, wall time: waiting for the CPU and '
        f'idle time count; {total:.1f} s, start-up included):'
    )
    rows = []
    for (file, _, func), (_, _, _, cumtime, _) in stats.stats.items():
        if '/maglev_ros/nodes/' in file and (
            func.startswith('_on_') or func in ('publish', 'on_message')  # on_message: recorder
        ):
            rows.append((cumtime, f'{Path(file).stem}.{func}'))
    for cumtime, name in sorted(rows, reverse=True)[:top]:
        print(f'        {name:<40} {100 * cumtime / total:5.1f} % (with callees)')
    own = sorted(
        ((tottime, f'{Path(file).name}:{func}') for (file, _, func), (_, _, tottime, _, _)
         in stats.stats.items()),
        reverse=True,
    )[:top]  # fmt: skip
    print('      own time:')
    for tottime, name in own:
        print(f'        {name:<40} {100 * tottime / total:5.1f} %')


class _Pinger:
    """Publishes stamped JointState pings at ``rate`` Hz in bursts every ``pace`` s."""

    def __init__(self, rate: float, context=None, pace: float = 1e-3) -> None:
        import rclpy
        from sensor_msgs.msg import JointState

        from maglev_ros.nodes.qos import SENSOR_QOS

        self.node = rclpy.create_node('bench_pinger', context=context)
        self.pub = self.node.create_publisher(JointState, PING, SENSOR_QOS)
        self.msg = JointState()
        self.msg.effort = [0.0] * 4
        self.sent = 0
        self.start = None
        self.rate = rate
        self.node.create_timer(pace, self.tick)

    def tick(self) -> None:
        from maglev_ros.nodes.messages import split_stamp

        now = time.monotonic()
        if self.start is None:
            if self.pub.get_subscription_count() < 2:  # echo_1 and the observer
                return
            self.start = now
        due = int((now - self.start) * self.rate) + 1
        for k in range(self.sent, min(due, self.sent + 50)):
            sec, nanosec = split_stamp(1_000_000_000 + round(k * 1e9 / self.rate))
            self.msg.header.stamp.sec, self.msg.header.stamp.nanosec = sec, nanosec
            self.pub.publish(self.msg)
            self.sent = k + 1


def _echo(name: str, source: str, target: str, context=None):
    import rclpy
    from sensor_msgs.msg import JointState

    from maglev_ros.nodes.qos import SENSOR_QOS

    node = rclpy.create_node(name, context=context)
    pub = node.create_publisher(JointState, target, SENSOR_QOS)
    node.create_subscription(JointState, source, pub.publish, SENSOR_QOS)
    return node


def pingpong_child(which: list[str], rate: float) -> int:
    """Run pinger and/or echo nodes in this process on the package's executor until SIGINT.

    Parameters
    ----------
    which : list of str
        Some of ``pinger``, ``echo_1``, ``echo_2``.
    rate : float
        Pings per second, Hz.
    """
    from maglev_ros.nodes.runtime import run_nodes

    factories = {
        'pinger': lambda: _Pinger(rate).node,
        'echo_1': lambda: _echo('bench_echo_1', PING, ECHO),
        'echo_2': lambda: _echo('bench_echo_2', ECHO, PONG),
    }
    return run_nodes([factories[w] for w in which], [sys.argv[0]], 'closed_loop', ())


# ---------------------------------------------------------------------- observer
class Observer:
    """Stores the arrival time (ns, monotonic) and raw bytes of each of its streams.

    Parameters
    ----------
    *streams : (str, type, QoSProfile)
        Topic, message class and QoS of each stream (the samples first, the
        answers last); ``received[i]`` holds stream i's messages.
    """

    def __init__(self, *streams) -> None:
        import rclpy

        from maglev_ros.nodes.runtime import Spinner

        self.context = rclpy.Context()
        rclpy.init(context=self.context, args=[])
        self.node = rclpy.create_node('closed_loop_observer', context=self.context)
        self.received: list[list[tuple[int, bytes]]] = [[] for _ in streams]
        clock = time.monotonic_ns
        for (topic, cls, qos), store in zip(streams, self.received, strict=True):
            self.node.create_subscription(
                cls, topic, lambda data, store=store: store.append((clock(), data)), qos, raw=True
            )
        self.types = [cls for _, cls, _ in streams]
        self.spinner = Spinner(self.context, [self.node])

    @property
    def samples(self) -> list[tuple[int, bytes]]:
        """The first stream's messages."""
        return self.received[0]

    @property
    def answers(self) -> list[tuple[int, bytes]]:
        """The last stream's messages."""
        return self.received[-1]

    @staticmethod
    def stamps(messages) -> np.ndarray:
        """Stamps of raw stamped messages (a header's, or a ``/clock``'s time), ns.

        Parameters
        ----------
        messages : list of (int, bytes)
            Arrival time and raw message: the stamp follows the CDR header.
        """
        unpack = struct.Struct('<iI').unpack_from
        out = np.empty(len(messages), dtype=np.int64)
        for i, (_, data) in enumerate(messages):
            sec, nanosec = unpack(data, 4)
            out[i] = sec * 1_000_000_000 + nanosec
        return out

    def close(self) -> None:
        """Stop spinning and shut the observer's context down."""
        import rclpy

        self.spinner.close()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _percentiles(latency_ns: np.ndarray) -> tuple[float, float]:
    """Median and 99th percentile, us."""
    if latency_ns.size == 0:
        return float('nan'), float('nan')
    return tuple(float(v) * 1e-3 for v in np.percentile(latency_ns, [50, 99]))


def _wait(predicate, what: str, procs: Processes, timeout: float = 180.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if not procs.running():
            raise SystemExit(f'a process ended while waiting for {what}; output:\n{procs.tail()}')
        if time.monotonic() > deadline:
            raise SystemExit(f'timed out waiting for {what}; output:\n{procs.tail()}')
        time.sleep(0.05)


def _cpu_report(names: dict[int, str], cpu: dict[int, float], threads, wall: float) -> float:
    """Print CPU per process (and per thread of a single process); return the total, s."""
    for pid, name in names.items():
        if cpu[pid] > 0.005 * wall:
            print(f'    {name:<32} pid {pid:>7}: CPU {100 * cpu[pid] / wall:5.1f} % of a core')
    if threads is not None:
        for name, seconds in sorted(threads.items(), key=lambda kv: -kv[1]):
            if seconds > 0.01 * wall:
                print(f'        thread {name:<24}: {100 * seconds / wall:5.1f} %')
    total = sum(cpu.values())
    print(f'    total CPU {100 * total / wall:.1f} % of a core', flush=True)
    return total


def _window(procs: Processes, seconds: float, observer: Observer):
    """Measure CPU over ``seconds`` of wall time; return (t0_ns, t1_ns, names, cpu, threads)."""
    names = procs.names()
    single = next(iter(names)) if len(names) == 1 else None
    cpu0 = {pid: cpu_seconds(pid) for pid in names}
    threads0 = thread_cpu_seconds(single) if single else None
    t0 = time.monotonic_ns()
    time.sleep(seconds)
    t1 = time.monotonic_ns()
    cpu = {pid: cpu_seconds(pid) - cpu0[pid] for pid in names}
    threads = None
    if single:
        after = thread_cpu_seconds(single)
        threads = {k: v - threads0.get(k, 0.0) for k, v in after.items()}
    return t0, t1, names, cpu, threads


def sensor_to_command(
    arrival: np.ndarray,
    stamps: np.ndarray,
    estimate_stamps: np.ndarray,
    command_arrival: np.ndarray,
    t0: int,
    t1: int,
) -> tuple[np.ndarray, str | None]:
    """Latency from each sample's arrival to the arrival of the command computed from it.

    The controller (``trigger: estimate``) answers each estimate once, in stamp
    order: command j answers estimate j, whose stamp names the newest sample
    it used. Commands carry no stamp, so the pairing is by count; it is void
    when the counts differ (the controller skipped estimates) or the sample
    was never received (lost).

    Parameters
    ----------
    arrival, stamps : ndarray of int, shape (N,)
        Arrival time (ns, monotonic) and stamp (ns) of each ``/clock`` (one a burst).
    estimate_stamps : ndarray of int, shape (M,)
        Stamps of the estimates received, in arrival order.
    command_arrival : ndarray of int, shape (C,)
        Arrival time of each command.
    t0, t1 : int
        The measured window (ns, monotonic): commands arriving in it count.

    Returns
    -------
    latency : ndarray of int
        ns, one per paired command in the window.
    why : str or None
        Why there is no valid latency (None: valid).
    """
    empty = np.empty(0, dtype=np.int64)
    if not np.all(np.diff(stamps) > 0):
        return empty, "the samples' stamps do not increase"
    if abs(estimate_stamps.size - command_arrival.size) > 3:  # a few in flight at the stop
        return empty, (
            f'{estimate_stamps.size} estimates but {command_arrival.size} commands: the '
            'controller did not answer each estimate'
        )
    n = min(estimate_stamps.size, command_arrival.size)
    index = np.searchsorted(stamps, estimate_stamps[:n])
    last = np.minimum(index, stamps.size - 1)
    found = (index < stamps.size) & (stamps[last] == estimate_stamps[:n])
    window = (command_arrival[:n] >= t0) & (command_arrival[:n] < t1)
    if not found[window].all():
        return empty, f'{int((~found[window]).sum())} estimated samples were not received'
    latency = command_arrival[:n][window] - arrival[index[window]]
    if latency.size and latency.min() < 0:
        return latency, 'a command arrived before its sample: the pairing is off'
    return latency, None


#: per layout, the subscribers each topic must have before the simulator resumes
#: (the observer's own counted)
SUBSCRIBERS = {
    'composed': {COMMAND_TOPIC: 1},  # the observer, until the first command
    'separate': {  # + recorder, identifier; estimator
        field_topic(0): 3,
        CURRENTS_TOPIC: 2,  # estimator, recorder
        CLOCK_TOPIC: 2,  # observer, recorder
        COMMAND_TOPIC: 4,  # observer, simulator, identifier, recorder
    },
}


def run_graph(
    label: str,
    commands: list[list[str]],
    env: dict,
    seconds: float,
    subscribers: dict[str, int],
    trace: Path | None = None,
) -> dict:
    """Run the graph, resume the simulator once matched, measure; print and return figures.

    Parameters
    ----------
    label : str
        Set-up name.
    commands : list of list of str
        The processes' argv.
    env : dict
        Their environment.
    seconds : float
        s of wall time measured.
    subscribers : dict
        Topic -> subscribers it must have matched before the simulator resumes.
    trace : Path, optional
        The composed layout: the figures come from the process's own
        :class:`_LoopTrace` written there (``CLOSED_LOOP_TRACE``); the observer
        only waits for the first command, then unsubscribes.
    """
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import SetBool

    from maglev_ros import topics
    from maglev_ros.nodes.qos import LOCKSTEP_COMMAND_QOS, SENSOR_QOS

    command_stream = (topics.COMMAND_TOPIC, Float64MultiArray, LOCKSTEP_COMMAND_QOS)
    if trace is None:
        observer = Observer(  # /clock: once per burst, stamped with its last sample
            (topics.CLOCK_TOPIC, Clock, SENSOR_QOS),
            (topics.ESTIMATE_TOPIC, Odometry, SENSOR_QOS),
            command_stream,
        )
    else:
        observer = Observer(command_stream)
        env = env | {_TRACE_ENV: str(trace)}
    node = observer.node
    procs = Processes(commands, env)
    try:
        client = node.create_client(SetBool, topics.SIMULATOR_PAUSE_SERVICE)

        def matched():
            # composed, the estimator, the controller, the identifier and the recorder
            # take what they need in this process: no subscriptions to wait for
            return (
                all(node.count_subscribers(t) >= n for t, n in subscribers.items())
                and node.count_publishers(topics.ESTIMATE_TOPIC) >= 1
                and node.count_publishers(topics.COMMAND_TOPIC) >= 1
                and client.service_is_ready()
            )

        print(f'{label}: starting (the first start compiles numba kernels) ...', flush=True)
        _wait(matched, 'the graph to match its topics', procs)
        time.sleep(2.0)  # both ends of every match (readers and writers)
        future = client.call_async(SetBool.Request(data=False))
        _wait(future.done, 'the simulator to resume', procs, 30.0)
        _wait(lambda: len(observer.answers) > 0, 'the first command', procs, 60.0)
        if trace is not None:  # nothing published to another process from here on
            for sub in list(node.subscriptions):
                node.destroy_subscription(sub)
        time.sleep(1.0)  # steady
        print(f'{label}: running {seconds:g} s ...', flush=True)
        t0, t1, names, cpu, threads = _window(procs, seconds, observer)
        received = [list(r) for r in observer.received]
    finally:
        procs.stop()
        observer.close()
    wall = (t1 - t0) * 1e-9
    crashed = any('crashed' in line for line in procs.lines)
    if trace is not None:
        if not trace.exists():
            raise SystemExit(f'{label}: no trace written; output:\n{procs.tail()}')
        rtf, latency, bursts = traced_figures(trace, t0, t1)
        why = None if latency.size else 'no command in the window'
        counts = f'{bursts} bursts, {latency.size} commands (timed in the process)'
    else:
        samples, estimates, answers = received
        arrival = np.array([t for t, _ in samples], dtype=np.int64)
        stamps = observer.stamps(samples)
        in_window = (arrival >= t0) & (arrival < t1)
        times, span = arrival[in_window], stamps[in_window]
        rtf = float(np.ptp(span) / max(np.ptp(times), 1)) if times.size > 1 else 0.0
        command_arrival = np.array([t for t, _ in answers], dtype=np.int64)
        # the controller's zero commands while it waits for a first estimate pair with none
        first = estimates[0][0] if estimates else t1
        command_arrival = command_arrival[command_arrival >= first]
        latency, why = sensor_to_command(
            arrival, stamps, observer.stamps(estimates), command_arrival, t0, t1
        )
        counts = (
            f'{int(in_window.sum())} bursts, {len(estimates)} estimates, {len(answers)} commands'
        )
    med, p99 = _percentiles(latency) if why is None else (float('nan'), float('nan'))
    print(
        f'{label}: real-time factor {rtf:.3f} over {wall:.1f} s ({counts}); sensor-to-command '
        f'latency median {med:.0f} us, 99th percentile {p99:.0f} us; crashed {crashed}'
    )
    if why is not None:
        print(f'    latency not valid: {why}')
    total = _cpu_report(names, cpu, threads, wall)
    return {'rtf': rtf, 'median': med, 'p99': p99, 'cpu': total / wall, 'crashed': crashed}


def run_pingpong(
    label: str, commands: list[list[str]], env: dict, seconds: float, rate: float
) -> dict:
    """Run the ping-pong, measure; print and return figures.

    Parameters
    ----------
    label : str
        Set-up name.
    commands : list of list of str
        The processes' argv.
    env : dict
        Their environment.
    seconds : float
        s of wall time measured.
    rate : float
        Samples (pings) per second expected, Hz.
    """
    from sensor_msgs.msg import JointState

    from maglev_ros.nodes.qos import SENSOR_QOS

    observer = Observer((PING, JointState, SENSOR_QOS), (PONG, JointState, SENSOR_QOS))
    procs = Processes(commands, env)
    try:
        print(f'{label}: starting ...', flush=True)
        _wait(lambda: len(observer.answers) > 0, 'the first pong', procs, 120.0)
        time.sleep(1.0)
        print(f'{label}: running {seconds:g} s ...', flush=True)
        t0, t1, names, cpu, threads = _window(procs, seconds, observer)
        pings, pongs = list(observer.samples), list(observer.answers)
    finally:
        procs.stop()
        observer.close()
    wall = (t1 - t0) * 1e-9
    sent = dict(zip(Observer.stamps(pings).tolist(), (t for t, _ in pings), strict=True))
    back = [(t, s) for (t, _), s in zip(pongs, Observer.stamps(pongs).tolist(), strict=True)]
    latency = np.array(
        [t - sent[s] for t, s in back if t0 <= t < t1 and s in sent], dtype=np.int64
    )
    n_pings = sum(1 for t, _ in pings if t0 <= t < t1)
    med, p99 = _percentiles(latency)
    print(
        f'{label}: {n_pings} pings in {wall:.1f} s = {n_pings / (rate * wall):.3f} of '
        f'{rate:g} Hz; '
        f'ping-to-pong latency (two echoes) median {med:.0f} us, 99th percentile {p99:.0f} us '
        f'({latency.size} pongs)'
    )
    if n_pings < 0.99 * rate * wall or latency.size < 0.99 * n_pings:
        print('    the ping-pong fell behind: its latency is queueing, not transport')
    total = _cpu_report(names, cpu, threads, wall)
    return {'median': med, 'p99': p99, 'cpu': total / wall}


def main() -> int:
    """Run the set-ups and print their figures."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=20.0, help='s of wall time per set-up')
    ap.add_argument('--only', choices=('composed', 'separate'), help='one layout only')
    ap.add_argument(
        '--param', action='append', default=[], metavar='NODE:NAME:=VALUE',
        help='override a node parameter (YAML value), e.g. controller:sample_rate:=1000.0',
    )  # fmt: skip
    ap.add_argument(
        '--profile', action='store_true',
        help='composed: profile the executor thread (cProfile; slows it) and print where '
        'its time goes',
    )  # fmt: skip
    ap.add_argument('--child', help=argparse.SUPPRESS)
    ap.add_argument('--values', help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child == 'graph':
        return composed_graph_child(json.loads(args.values))
    if args.child:
        return pingpong_child(args.child.split(','), float(args.values))
    try:
        if not args.seconds > 0:
            raise BenchmarkArgumentError(f'--seconds must be > 0, got {args.seconds}')
        for text in args.param:
            parse_param(text)
    except BenchmarkArgumentError as err:
        print(f'closed_loop: error: {err}', file=sys.stderr)
        return 2
    env = benchmark_environment(DOMAIN)
    tmp = Path(tempfile.mkdtemp(prefix='closed_loop_'))
    py, me = sys.executable, str(Path(__file__).resolve())
    print(
        f'load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs, nice '
        f'{os.nice(0)}; overrides: {" ".join(args.param) or "none"}',
        flush=True,
    )
    results = {}
    try:
        for layout in ('composed', 'separate'):
            if args.only not in (None, layout):
                continue
            try:
                values = graph_parameters(args.param, str(tmp / f'bag_{layout}'), layout)
            except Exception as err:  # noqa: BLE001 - a YAML value that does not parse
                print(f'closed_loop: error: --param: {err}', file=sys.stderr)
                return 2
            rate = float(values['simulator'].get('sample_rate', 5000.0))
            if layout == 'composed':
                graph = [[py, me, '--child', 'graph', '--values', json.dumps(values)]]
                pingpong = [[py, me, '--child', ','.join(_PINGPONG), '--values', str(rate)]]
            else:
                graph = [
                    [py, '-m', f'maglev_ros.nodes.{node}', '--ros-args']
                    + [a for k, v in values[node].items() for a in ('-p', f'{k}:={_yaml_text(v)}')]
                    for node in NODES
                ]
                pingpong = [[py, me, '--child', w, '--values', str(rate)] for w in _PINGPONG]
            graph_env = env
            if args.profile and layout == 'composed':
                graph_env = env | {_PROFILE_ENV: str(tmp / 'composed.prof')}
            results[layout] = (
                run_graph(
                    f'graph {layout}',
                    graph,
                    graph_env,
                    args.seconds,
                    SUBSCRIBERS[layout],
                    tmp / 'trace.npz' if layout == 'composed' else None,
                ),
                run_pingpong(f'ping-pong {layout}', pingpong, env, args.seconds, rate),
            )
        if args.profile and (tmp / 'composed.prof').exists():
            print_profile(tmp / 'composed.prof')
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print('summary (targets: real-time factor >= 1.0, latency within 2x the ping-pong):')
    for layout, (g, p) in results.items():
        if np.isnan(g['median']):
            latency = 'latency not valid (the graph fell behind)'
        else:
            latency = (
                f'latency over the ping-pong (baseline, same run): median '
                f'{g["median"] / p["median"]:.2f}x ({g["median"]:.0f} / {p["median"]:.0f} us), '
                f'99th percentile {g["p99"] / p["p99"]:.2f}x ({g["p99"]:.0f} / {p["p99"]:.0f} us)'
            )
        print(
            f'  {layout:<9} real-time factor {g["rtf"]:.3f}; {latency}; graph CPU '
            f'{100 * g["cpu"]:.0f} % of a core'
        )
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
