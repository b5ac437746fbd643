"""The closed-loop lab session as one process: levitate, settle, excite, record exactly N samples.

The graph of the issue's main job, composed on one executor
(:class:`~maglev_ros.nodes.bringup.Bringup`):

* the simulator (lockstep, magnet free, sensor noise and quantisation, sensor
  delay, coil dynamics), started paused;
* the estimator (``filter``, default the KF) and the controller (LQR,
  ``delay_commands``: the board's one sample of command latency) with its
  excitation (:mod:`maglev_ros.control.excitation`, an input disturbance
  starting with the recording);
* the online identifier (x and y field of sensor 0 against the pair inputs)
  and the recorder (``record_from``: the first recorded sample on).

Order of events. Discovery is awaited on both sides of every topic, then
the magnet, at rest at the equilibrium, levitates for ``settle`` s of
simulated time; the simulator pauses by itself after exactly that many
samples (:meth:`SimulatorNode.pause_after`), the last sample's command waits
in its queue, the settling is checked on the true state (RMS of the
position error over the last 0.1 s) and the identifier is reset (its
service). The simulation resumes and pauses again after exactly ``samples``
more samples: the bag and the identifier get those samples, each with its
command and excitation, and nothing else. The first recorded command is the
first to carry the excitation (computed at the last settling sample and
published, ``delay_commands``, for the next).

Every node is there from the start: a subscription matched just before the
recording could have its first messages handled after those of other
topics, and the recorder would log them at the previous ``/clock``.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from rclpy.parameter import Parameter

from maglev_ros.control.excitation import CommandExcitation
from maglev_ros.topics import (
    CLOCK_TOPIC,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    ESTIMATE_TOPIC,
    EXCITATION_TOPIC,
    IDENTIFIER_RESET_SERVICE,
    REFERENCE_TOPIC,
    TRUE_STATE_TOPIC,
    command_channel,
    current_channel,
    excitation_channel,
    field_channel,
    field_topic,
)

__all__ = [
    'BOARD_IDENTIFIER_CHANNELS',
    'IDENTIFIER_CHANNELS',
    'LabGraphSettings',
    'LabRun',
    'OnlineEstimate',
    'controller_parameters',
    'estimator_parameters',
    'identifier_parameters',
    'online_estimate',
    'overrides',
    'pair_channel',
    'run_closed_loop_lab',
    'wait_recorded',
]

SETTLE_WINDOW = 0.1  # s of simulated time: the settling check's moving RMS
WAIT_S = 60.0  # s, longest wait for discovery, draining and a single sample (JIT)


def pair_channel(pair: str, channel: Callable[[int], str] = command_channel) -> str:
    """Channel spec of an antisymmetric pair's input ``0.5 (c+ - c-)``, named ``u_<pair>``.

    Parameters
    ----------
    pair : {'x', 'y'}
        The coil pair (x+ x- or y+ y-).
    channel : callable
        Coil index to channel spec: :func:`~maglev_ros.topics.command_channel`
        (the total command, named ``u_<pair>``),
        :func:`~maglev_ros.topics.current_channel` (the currents applied, a
        board's input, also ``u_<pair>``) or
        :func:`~maglev_ros.topics.excitation_channel` (the excitation, ``r_<pair>``).

    Returns
    -------
    str
        E.g. ``u_x=0.5*maglev/currents/command:data[0]-0.5*maglev/currents/command:data[1]``.
    """
    plus = {'x': 0, 'y': 2}[pair]
    name = 'r' if channel is excitation_channel else 'u'
    return f'{name}_{pair}=0.5*{channel(plus)}-0.5*{channel(plus + 1)}'


#: The identifier node's channels: the x and y field of sensor 0 against the pair inputs.
IDENTIFIER_CHANNELS = (
    (f'Bx_0={field_channel(0, "x")}', f'By_0={field_channel(0, "y")}'),
    (pair_channel('x'), pair_channel('y')),
)
#: On a board: against the pair currents applied (each record's PWM, stamped with its
#: field): a command reaches the coils a read and a link's round trip after its sample.
BOARD_IDENTIFIER_CHANNELS = (
    IDENTIFIER_CHANNELS[0],
    (pair_channel('x', current_channel), pair_channel('y', current_channel)),
)


@dataclass(frozen=True)
class LabGraphSettings:
    """What the closed-loop lab runs.

    Attributes
    ----------
    params : str
        Parameter set (plant, estimator and controller).
    samples : int
        Samples to record after settling.
    settle : float
        s of simulated time before the recording.
    sample_rate : float
        Hz.
    noise, quantization : float
        Sensor noise (T rms) and resolution (T per LSB).
    sensor_delay : int
        Samples.
    coil_dynamics : bool
        Coil L/R electrics.
    field_model : str
        The simulator's field model.
    seed : int
        Seed of the sensor noise.
    sensors : tuple of int
        Sensors whose fields are recorded.
    storage : str
        ``mcap`` or ``sqlite3``.
    filter : str
        The estimator's filter.
    excitation : CommandExcitation
        The controller's excitation; its ``start`` is set to the first recorded sample.
    identifier_orders : tuple
        ``(na, nb, nk)`` of the identifier node, ny*ny and ny*nu values row by
        row for :data:`IDENTIFIER_CHANNELS` (default: x 7 9 1 and y 6 6 1, decoupled).
    initial_covariance : float
        The identifier's ``P0 = p0 I`` (fields in T: large).
    realtime : bool
        Run on the wall clock (:func:`run_closed_loop_lab`, "Real time").
    control_rate : float
        Real time: estimates and commands per second, Hz (divides ``sample_rate``).
    """

    params: str = 'maggy_v2'
    samples: int = 25000
    settle: float = 1.0
    sample_rate: float = 5000.0
    noise: float = 1e-4
    quantization: float = 0.098e-3
    sensor_delay: int = 1
    coil_dynamics: bool = True
    field_model: str = 'fast'
    seed: int = 0
    sensors: tuple[int, ...] = (0,)
    storage: str = 'mcap'
    filter: str = 'kf'
    excitation: CommandExcitation = field(
        default_factory=lambda: CommandExcitation('prbs', 0.1, (0.0, 0.2), 'pairs')
    )
    identifier_orders: tuple = ((7, 0, 0, 6), (9, 0, 0, 6), (1, 1, 1, 1))
    initial_covariance: float = 1e10
    realtime: bool = False
    control_rate: float = 1000.0

    @property
    def control_excitation(self) -> CommandExcitation:
        """The excitation in the controller's samples (real time: at ``control_rate``).

        Its band (fractions of Nyquist) and length (samples) are given at
        ``sample_rate``; at the control rate the same frequencies are a
        ``sample_rate / control_rate`` times larger fraction (at most 1).
        """
        e = self.excitation
        if not self.realtime:
            return e
        ratio = self.sample_rate / self.control_rate
        band = (min(e.band[0] * ratio, 1.0), min(e.band[1] * ratio, 1.0))
        return replace(e, band=band, length=max(1, int(round(e.length / ratio))))

    @property
    def settle_samples(self) -> int:
        """Index of the last sample before the recording (the settling's samples)."""
        return max(1, int(round(self.settle * self.sample_rate)))


@dataclass(frozen=True)
class OnlineEstimate:
    """The online identifier's final state.

    Attributes
    ----------
    model : PolyModel
        Its ARX estimate (all rows), raw (not detrended) signals.
    samples : int
        Samples it was given.
    covariance_trace : float
        Trace of its covariance.
    fit : ndarray, shape (ny,)
        One-step prediction fit over its window, %.
    forgetting : float
        Its forgetting factor.
    """

    model: object
    samples: int
    covariance_trace: float
    fit: np.ndarray
    forgetting: float


@dataclass(frozen=True)
class LabRun:
    """What the closed-loop session did.

    Attributes
    ----------
    samples : int
        Samples recorded (published after settling).
    settle_s : float
        Simulated s before the recording.
    settle_rms : ndarray, shape (3,)
        RMS of the true position error over the last 0.1 s of settling, m.
    settled : bool
        Whether that RMS is below 0.1 mm on every axis.
    simulated_s : float
        Simulated time at the end, s.
    wall_s : float
        Wall time of the recording, s.
    timeouts : int
        Lockstep command timeouts of the simulator (0: every sample had its command).
    overruns : int
        Real time: times the simulator fell behind the wall clock by more than its
        backlog allows and skipped ahead (0: it kept up).
    crashed : bool
    crash_reason : str
    controller : dict
        Controller counters: ``saturated`` commands, ``level`` and ``message``.
    identifier : OnlineEstimate or None
        None if it got no sample.
    positions : ndarray, shape (n, 3), optional
        A board run: the estimated positions over the window, m (no true state).
    """

    samples: int
    settle_s: float
    settle_rms: np.ndarray
    settled: bool
    simulated_s: float
    wall_s: float
    timeouts: int
    crashed: bool
    crash_reason: str
    controller: dict
    identifier: OnlineEstimate | None
    overruns: int = 0
    positions: np.ndarray | None = None


def overrides(**values) -> list:
    """Return ROS parameter overrides ``name=value`` for a node of the lab's graph.

    Parameters
    ----------
    **values
        Parameter name to value.
    """
    return [Parameter(k, value=v) for k, v in values.items()]


def estimator_parameters(s: LabGraphSettings, **more) -> dict:
    """Return the lab's estimator parameters: parameter set, filter, rate and sensors.

    Parameters
    ----------
    s : LabGraphSettings
    **more
        Further parameters (e.g. ``intra_process``).
    """
    return dict(
        params=s.params,
        filter=s.filter,
        sample_rate=s.sample_rate,
        sensor_delay=s.sensor_delay,
        sensor_noise=max(s.noise, 1e-6),
        quantization=s.quantization,
        **more,
    )


def controller_parameters(s: LabGraphSettings, excitation: CommandExcitation, **more) -> dict:
    """Return the lab's controller parameters: the LQR of the set and its excitation.

    Parameters
    ----------
    s : LabGraphSettings
    excitation : CommandExcitation
        In the controller's samples, its ``start`` set.
    **more
        Further parameters (rate, trigger, delays).
    """
    e = excitation
    return dict(
        params=s.params,
        coil_dynamics=s.coil_dynamics,
        excitation_signal=e.signal,
        excitation_amplitude=e.amplitude,
        excitation_band=list(e.band),
        excitation_pattern=e.pattern,
        excitation_seed=e.seed,
        excitation_length=e.length,
        excitation_cycles=e.cycles,
        excitation_start=e.start,
        **more,
    )


def identifier_parameters(s: LabGraphSettings, channels=None, **more) -> dict:
    """Return the lab's identifier parameters: the seed's x and y orders, in this process.

    Parameters
    ----------
    s : LabGraphSettings
    channels : tuple of (outputs, inputs), optional
        Default :data:`IDENTIFIER_CHANNELS`.
    **more
        Further parameters (trigger, window).
    """
    outputs, inputs = channels or IDENTIFIER_CHANNELS
    return dict(
        outputs=list(outputs),
        inputs=list(inputs),
        na=list(s.identifier_orders[0]),
        nb=list(s.identifier_orders[1]),
        nk=list(s.identifier_orders[2]),
        initial_covariance=s.initial_covariance,
        publish_rate=1.0,
        **more,
    )


def _matched(node, topic: str, publisher: bool) -> int:
    """Count the peers matched by ``node``'s publisher (subscription) on ``topic`` (-1: none)."""
    name = '/' + topic.lstrip('/')
    if publisher:
        counts = [p.get_subscription_count() for p in node.publishers if p.topic_name == name]
    else:
        counts = [s.get_publisher_count() for s in node.subscriptions if s.topic_name == name]
    return min(counts) if counts else -1


class _SettleWatch:
    """Position error of the true state over the settling's last window.

    Takes ``maglev/state/true`` from the simulator's tap
    (:func:`~maglev_ros.nodes.intra_process.tap`: the bytes it serialised, in
    its thread) and decodes only the messages stamped in the window, ns
    ``[first_ns, last_ns]``: nothing else is spent on the 5 kHz stream.
    """

    def __init__(self, context, topic: str, z_eq: float, first_ns: int, last_ns: int) -> None:
        import struct

        from nav_msgs.msg import Odometry
        from rclpy.serialization import deserialize_message

        from maglev_ros.nodes import intra_process

        self._errors: list[tuple[float, float, float]] = []
        self._z_eq = z_eq
        self._window = (first_ns, last_ns)
        self._stamp = struct.Struct('<iI')
        self._decode = lambda raw: deserialize_message(raw, Odometry)
        self._tap = intra_process.tap(context, topic)
        self._tap.connect(self._on_states, 'maglev_lab_settling')

    def _on_states(self, messages: list) -> None:
        first, last = self._window
        for raw in messages:
            sec, nanosec = self._stamp.unpack_from(raw, 4)
            if first <= sec * 1_000_000_000 + nanosec <= last:
                p = self._decode(raw).pose.pose.position
                self._errors.append((p.x, p.y, p.z - self._z_eq))

    def close(self) -> None:
        """Stop taking the states."""
        self._tap.disconnect(self._on_states)

    def rms(self) -> np.ndarray:
        """RMS of the window's position error per axis, m, shape (3,) (NaN: none yet)."""
        if not self._errors:
            return np.full(3, np.nan)
        return np.sqrt(np.mean(np.square(np.array(self._errors)), axis=0))


def run_closed_loop_lab(
    settings: LabGraphSettings,
    bag: Path,
    stop=None,
    progress: Callable[[str, int, int], None] | None = None,
) -> LabRun:
    """Run the closed-loop lab session (see the module docstring) and record the bag.

    Parameters
    ----------
    settings : LabGraphSettings
        What to run.
    bag : Path
        Bag directory to create.
    stop : StopSignals or threading.Event, optional
        Ends the run when a stop signal arrives.
    progress : callable, optional
        ``progress(stage, done, total)`` with stage ``settling`` or
        ``recording``, samples, called while waiting.

    Returns
    -------
    LabRun

    Raises
    ------
    KeyboardInterrupt
        On a stop signal (the bag is finalised first).
    RuntimeError
        If the graph does not come up or stops answering (names what).
    """
    import os

    from rclpy.node import Node
    from std_srvs.srv import Trigger

    from maglev_ros.nodes.bringup import Bringup
    from maglev_ros.nodes.controller import ControllerNode
    from maglev_ros.nodes.estimator import EstimatorNode
    from maglev_ros.nodes.identifier import IdentifierNode
    from maglev_ros.nodes.recorder import RecorderNode
    from maglev_ros.nodes.simulator import SimulatorNode
    from maglev_ros.physics import make_model
    from maglev_ros.physics.equilibria import find_equilibria

    s = settings
    rt = s.realtime
    settle_n = s.settle_samples
    last = settle_n + s.samples  # index of the last recorded sample
    period_ns = round(1e9 / s.sample_rate)
    # lockstep: the excitation starts with the command computed at sample settle_n,
    # published (delay_commands) for sample settle_n + 1, the first recorded command
    excitation = replace(s.control_excitation, start=settle_n / s.sample_rate)
    z_eq = find_equilibria(make_model(s.params))[0].z
    topics = [
        *(field_topic(k) for k in s.sensors),
        CURRENTS_TOPIC,
        COMMAND_TOPIC,
        EXCITATION_TOPIC,
        TRUE_STATE_TOPIC,
        CLOCK_TOPIC,
    ]
    report = progress or (lambda stage, done, total: None)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with Bringup() as lab:
        ctx = lab.context
        sim = lab.add(
            SimulatorNode(
                context=ctx,
                parameter_overrides=overrides(
                    params=s.params,
                    field_model=s.field_model,
                    magnet='free',
                    sample_rate=s.sample_rate,
                    coil_dynamics=s.coil_dynamics,
                    sensor_delay=s.sensor_delay,
                    sensor_noise=s.noise,
                    sensor_quantization=s.quantization,
                    seed=s.seed,
                    mode='realtime' if rt else 'lockstep',
                    pace_period=1.0 / s.control_rate,  # real time: one burst per command
                    start_paused=True,
                    sensors=list(range(len(make_model(s.params).params.sensors))),
                    marker_rate=0.0,
                    command_timeout=WAIT_S,
                ),
            )
        )
        # real time: samples, estimates and commands handed over in the simulator's
        # thread (intra_process), one estimate and one command per control period
        realtime_estimator = dict(publish_rate=s.control_rate, intra_process=True)
        est = lab.add(
            EstimatorNode(
                context=ctx,
                parameter_overrides=overrides(
                    **estimator_parameters(s, **(realtime_estimator if rt else {}))
                ),
            )
        )
        e = excitation
        realtime_controller = dict(
            sample_rate=s.control_rate,
            trigger='estimate',
            intra_process=True,
            command_delay=1,
            input_timeout=0.02,
        )
        ctrl = lab.add(
            ControllerNode(
                context=ctx,
                parameter_overrides=overrides(
                    **controller_parameters(
                        s,
                        e,
                        delay_commands=not rt,
                        **(realtime_controller if rt else dict(sample_rate=s.sample_rate)),
                    )
                ),
            )
        )
        first_s, last_s = (settle_n + 1) / s.sample_rate, last / s.sample_rate
        # both clocks: the identifier and the recorder take every topic from its
        # publisher's tap (no middleware hop, no executor callback per message)
        realtime_identifier = dict(
            trigger=field_topic(0),  # every sample, the commands held
            complete_on_next=True,  # a command answering a sample is its input
            identify_from=first_s,
            identify_until=last_s,
        )
        ident = lab.add(
            IdentifierNode(
                context=ctx,
                parameter_overrides=overrides(
                    **identifier_parameters(s, **(realtime_identifier if rt else {}))
                ),
            )
        )
        # from the first recorded sample, logged at the samples' stamps (a command at
        # the newest: the sample it follows); real time: to the last, the loop runs on
        recording = dict(record_from=first_s, log_clock='stamp')
        if rt:
            recording.update(record_until=last_s)
        recorder = lab.add(
            RecorderNode(
                context=ctx,
                parameter_overrides=overrides(
                    path=str(bag),
                    storage=s.storage,
                    topics=topics,
                    **recording,
                ),
            ),
            destroy_last=True,  # finalises the bag once the others are gone
        )
        watch_node = lab.add(Node('maglev_lab_settling', context=ctx))
        window = max(1, int(round(SETTLE_WINDOW * s.sample_rate)))
        watch = _SettleWatch(
            ctx,
            sim.resolve_topic_name(TRUE_STATE_TOPIC),
            z_eq,
            (settle_n - window + 1) * period_ns,
            settle_n * period_ns,
        )
        reset = watch_node.create_client(Trigger, IDENTIFIER_RESET_SERVICE)
        lab.start()
        try:
            if rt:
                run = _run_realtime(lab, s, sim, ctrl, ident, recorder, topics, report, stop)
            else:
                run = _run_lockstep(
                    lab, s, sim, est, ctrl, ident, recorder, watch_node, reset, topics, report,
                    stop,
                )  # fmt: skip
        finally:
            watch.close()
        return replace(run, settle_rms=watch.rms(), settled=bool(np.all(watch.rms() < 1e-4)))


def online_estimate(ident, sample_rate: float) -> OnlineEstimate | None:
    """Return the identifier's final state (None: it got no sample).

    Parameters
    ----------
    ident : IdentifierNode
        The lab's identifier.
    sample_rate : float
        Its samples per second, Hz (the model's sample time).
    """
    if not ident.samples:
        return None
    st = ident.identifier.status()
    return OnlineEstimate(
        ident.identifier.model(1.0 / sample_rate),
        int(ident.samples),
        float(st.covariance_trace),
        np.asarray(st.fit),
        ident.config.forgetting,
    )


def _lab_run(s, sim, ctrl, ident, recorded: int, wall: float) -> LabRun:
    """Return the figures of a finished run (the caller fills in the settling's RMS)."""
    status = ctrl.controller.status()
    return LabRun(
        samples=int(recorded),
        settle_s=s.settle_samples / s.sample_rate,
        settle_rms=np.full(3, np.nan),
        settled=False,
        simulated_s=float(sim.sim.time),
        wall_s=wall,
        timeouts=int(sim.counters['timeouts']),
        crashed=bool(sim.sim.crashed),
        crash_reason=sim.sim.reason,
        controller={
            'level': status.level,
            'message': status.message,
            'saturated': int(status.saturated),
            'commands': int(ctrl.commands),
        },
        identifier=online_estimate(ident, s.sample_rate),
        overruns=int(sim.counters['overruns']),
    )


def _run_lockstep(
    lab, s, sim, est, ctrl, ident, recorder, watch_node, reset, topics, report, stop
) -> LabRun:
    """Lockstep: pause after the settling, reset the identifier, record exactly the samples."""
    from std_srvs.srv import Trigger

    settle_n = s.settle_samples
    last = settle_n + s.samples
    publishers = {  # topic: (publisher node, subscriptions it must have matched)
        **{field_topic(k): (sim, 1) for k in sim.sensors},  # the estimator
        CURRENTS_TOPIC: (sim, 2),  # estimator, controller
        ESTIMATE_TOPIC: (est, 1),
        COMMAND_TOPIC: (ctrl, 1),  # the simulator (identifier, recorder: its tap)
    }
    lab.wait_until(
        lambda: (
            sim.command_publishers >= 1
            and len(recorder.subscribed) == len(topics)
            and recorder.metadata_complete
            and all(
                count >= 1
                for n in (est, ctrl, ident, recorder, watch_node)
                for count in _subscription_counts(n)
            )  # fmt: skip
            and all(_matched(n, t, True) >= k for t, (n, k) in publishers.items())
            and reset.service_is_ready()
        ),
        'the simulator, estimator, controller, identifier and recorder',
        stop=stop,
    )
    sim.pause_after(settle_n)
    sim.set_paused(False)
    _wait_paused(lab, sim, ctrl, settle_n, 'settling', report, stop)
    # the identifier starts afresh with the first recorded sample: every settling
    # sample reached it (one per command), then it is reset while nothing moves
    lab.wait_until(lambda: ident.samples >= settle_n + 1, 'the identifier (settling)', stop=stop)
    answer = reset.call_async(Trigger.Request())
    lab.wait_until(answer.done, 'the identifier reset', stop=stop)
    wall = time.monotonic()
    sim.pause_after(last)
    sim.set_paused(False)
    _wait_paused(lab, sim, ctrl, last, 'recording', report, stop, first=settle_n)
    wall = time.monotonic() - wall
    recorded = sim.sim.samples - settle_n
    wait_recorded(lab, recorder, ident, topics, recorded, stop)
    return _lab_run(s, sim, ctrl, ident, recorded, wall)


def _run_realtime(lab, s, sim, ctrl, ident, recorder, topics, report, stop) -> LabRun:
    """Real time: run on the wall clock through the settling and the recording window.

    Nothing pauses between them (a paused loop would go stale): the recorder
    (``record_from``, ``record_until``) and the identifier (``identify_from``,
    ``identify_until``) keep exactly the window's samples, with the commands
    in force at its start. The simulator pauses once a burst past its end.
    """
    settle_n = s.settle_samples
    last = settle_n + s.samples
    lab.wait_until(
        lambda: (
            len(recorder.subscribed) == len(topics)
            and recorder.metadata_complete
            and all(count >= 1 for count in _subscription_counts(recorder))
        ),
        'the simulator, estimator, controller, identifier and recorder',
        stop=stop,
    )
    # what start-up made stays out of the collector's way: a full collection of it
    # (~0.1 s) in the middle of the run would stall the loop's thread
    gc.freeze()
    # one burst beyond the window: the identifier completes a sample at the next one
    sim.pause_after(last + sim.session.burst)
    sim.set_paused(False)
    wall = [time.monotonic(), None]

    def stepped() -> int:
        n = sim.sim.samples
        if n > settle_n and wall[1] is None:
            wall[1] = time.monotonic()
        return n

    _wait_paused(
        lab, sim, ctrl, settle_n, 'settling', report, stop, realtime=True, samples=stepped
    )
    _wait_paused(
        lab, sim, ctrl, last + sim.session.burst, 'recording', report, stop, first=settle_n,
        realtime=True, samples=stepped,
    )  # fmt: skip
    wall_s = time.monotonic() - (wall[1] or wall[0])
    recorded = min(sim.sim.samples, last) - settle_n
    # /clock goes once a burst, commands and excitation once a command
    per_sample = [t for t in topics if t not in (CLOCK_TOPIC, COMMAND_TOPIC, EXCITATION_TOPIC)]
    wait_recorded(lab, recorder, ident, per_sample, recorded, stop)
    return _lab_run(s, sim, ctrl, ident, recorded, wall_s)


def wait_recorded(lab, recorder, ident, topics, recorded: int, stop) -> None:
    """Wait for ``recorded`` messages of each topic in the bag and as many identifier samples.

    Parameters
    ----------
    lab : Bringup
        The lab's graph (its wait).
    recorder : RecorderNode
    ident : IdentifierNode
    topics : list of str
        Topics with one message per sample.
    recorded : int
        Samples in the window.
    stop : StopSignals or threading.Event or None
        Ends the wait.
    """
    lab.wait_until(
        lambda: (
            all(recorder.counts['/' + t.lstrip('/')] >= recorded for t in topics)
            and ident.samples >= recorded
        ),
        'the recorder and the identifier',
        stop=stop,
    )


def _subscription_counts(node) -> list[int]:
    """Count the publishers matched by each subscription of ``node`` (not the set-point)."""
    skip = '/' + REFERENCE_TOPIC
    return [sub.get_publisher_count() for sub in node.subscriptions if sub.topic_name != skip]


def _wait_paused(
    lab,
    sim,
    ctrl,
    index,
    stage,
    report,
    stop,
    first: int = 0,
    realtime: bool = False,
    samples: Callable[[], int] | None = None,
) -> None:
    """Wait until the simulator stepped sample ``index`` (lockstep: paused, answered).

    Lockstep: paused after sample ``index`` and the controller's command for it
    queued. Real time: sample ``index`` stepped (the simulator runs on unless
    its ``pause_after`` is that sample). Raises RuntimeError when no sample is
    stepped for ``2 WAIT_S`` (the simulator holds a missing command after
    ``WAIT_S``: the graph stopped).
    """
    total = index - first
    last = [-1, time.monotonic()]
    count = samples or (lambda: sim.sim.samples)

    def done() -> bool:
        stepped = count()
        now = time.monotonic()
        if stepped != last[0]:
            last[:] = [stepped, now]
        elif now - last[1] > 2 * WAIT_S:
            raise RuntimeError(
                f'the {stage} stopped at sample {stepped}: no sample for {2 * WAIT_S:g} s'
            )
        report(stage, min(max(stepped - first, 0), total), total)
        if sim.sim.crashed:
            return True
        if realtime:
            return stepped >= index
        # paused after `index`; the controller's command for it is queued at the simulator
        return sim.paused and stepped >= index and ctrl.commands >= stepped + 1

    lab.wait_until(done, f'the {stage} ({total} samples)', timeout=1e9, stop=stop)
