"""The closed loop on a V4x PC-control board, built from plain settings.

What runs the magnet on a current (V4x) board from a PC: the board's one
sensor and its processed field (:class:`~maglev_ros.estimation.EstimatorConfig`
``measurement='board'``), a KF with that measurement model at the loop's
sample rate, the LQR at the same rate, as a
:class:`~maglev_ros.loop.ControlLoop` on a
:class:`~maglev_ros.loop.v4x_pc_plant.V4xPcPlant`.

The board applies pair differences only (x+ gets ``p_x``, x- ``-p_x``): the
LQR's common-mode part (the same current in every coil, which acts on the
height z) cannot reach the coils and is dropped by the plant's guard. The
height is not controlled then; it is held by the base magnets (the z mode of
the model is an undamped oscillation, stable, not unstable as x and y are).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..hardware.scaling import V4X_PWM_FULL_SCALE, CurrentScaling
from .control_loop import ControlLoop
from .v4x_pc_plant import DEFAULT_RATE, V4xPcPlant

#: s over which the excitation fades in at the start of the record (linearly).
EXCITATION_RAMP = 0.5

__all__ = [
    'V4xPcLoopSettings',
    'V4xPcRun',
    'board_model',
    'build_v4x_pc_loop',
    'run_v4x_pc_loop',
    'warm_up',
]


@dataclass(frozen=True)
class V4xPcLoopSettings:
    """What the loop on a V4x PC-control board runs.

    Attributes
    ----------
    params : str
        Parameter set the estimator and the controller believe (``maggy_v2``,
        ``maggy_v4`` or a YAML path).
    sensor : int
        Which sensor of the set the board reads (its mux channel 7).
    sample_rate : float
        Samples (and commands) per second, Hz.
    supply_voltage, coil_resistance : float
        V and ohm: the PWM scaling (255 counts at full duty).
    current_limit : float
        Largest commanded |current| per coil, A (default 1.7: the lab's host
        clamps the PWM at 150 of 255 counts, 1.76 A at 12 V and 4 ohm; at 1 A
        the LQR's noise-driven commands saturate, and a few late periods
        then lose the magnet: docs/benchmarks.md, ``v4x_pc_hold.py``).
    bias_states : bool
        Estimate a constant offset per axis (the baseline's error, a
        feedthrough slope's error).
    initial_bias_xy : float
        T: the x and y offsets' initial std (z: the estimator's 1 mT, where
        a magnet 10 % off moves the field by a few mT). The board's baseline
        is the mean of 1000 readings with the magnet absent, and the magnet
        held over the centre adds no x or y field there; 0.1 mT still covers a
        sensor 0.5 mm off the centre. At 1 mT the first readings' noise
        passed partly for an offset and the estimate left the magnet by up
        to 0.5 mm in its first 50 ms (the start peak of a 60 s hold).
    coil_dynamics : bool
        The coils' L/R lag in the LQR design.
    command_delay : int
        Samples of command delay in the LQR design (1: the plant sends the
        command of sample k with the request of sample k+1).
    sensor_noise : float
        T rms per axis the estimator assumes.
    angular_acceleration_noise : float
        The estimator's unmodelled torque per inertia, rad/s^2 rms
        (:class:`~maglev_ros.estimation.EstimatorConfig`).
    position_scale, current_scale : float
        The LQR's Bryson scales of x y z (m) and of the commands (A)
        (:class:`~maglev_ros.control.ControllerConfig`).
    realtime_priority : int
        ``SCHED_FIFO`` priority of the loop's thread while it runs, 1-99
        (:func:`~maglev_ros.realtime_priority.fifo_priority`); 0 (default): the
        normal policy.
    measure_feedthrough : bool
        Before the loop, with the magnet absent, measure what each coil pair
        leaves in the board's readings (the firmware's own compensation is a
        few percent off; :mod:`~maglev_ros.hardware.v4x_pc_feedthrough`), model
        it, then wait for the magnet. False: the magnet is in place already,
        and the firmware's compensation is taken as exact.
    magnet_timeout : float
        s to wait for the magnet after the measurement.
    """

    params: str = 'maggy_v2'
    sensor: int = 0
    sample_rate: float = DEFAULT_RATE
    supply_voltage: float = 12.0
    coil_resistance: float = 4.0
    current_limit: float = 1.7
    bias_states: bool = True
    initial_bias_xy: float = 1.0e-4
    coil_dynamics: bool = False
    command_delay: int = 1
    sensor_noise: float = 1.0e-4
    angular_acceleration_noise: float = 50.0
    position_scale: float = 1.0e-4
    current_scale: float = 1.0
    realtime_priority: int = 0
    measure_feedthrough: bool = True
    magnet_timeout: float = 60.0

    @property
    def scaling(self) -> CurrentScaling:
        """PWM counts per ampere of the board (255 counts at full duty)."""
        return CurrentScaling.from_supply(
            self.supply_voltage, self.coil_resistance, V4X_PWM_FULL_SCALE
        )


def board_model(params, sensor: int):
    """Return the physics model of ``params`` with only the board's sensor.

    Parameters
    ----------
    params : str or MaggyParameters
        Preset, YAML path or a loaded set.
    sensor : int
        Index of the sensor the board reads.

    Raises
    ------
    ValueError
        If the set has no such sensor.
    """
    from ..physics import MaggyParameters, load_parameters, make_model

    p = params if isinstance(params, MaggyParameters) else load_parameters(params)
    if not 0 <= sensor < len(p.sensors):
        raise ValueError(
            f'sensor must be 0 to {len(p.sensors) - 1} for {params!r}, got {sensor!r}'
        )
    return make_model(p.replace(sensors=(p.sensors[sensor],)))


def build_v4x_pc_loop(
    s: V4xPcLoopSettings, link, observers=(), excitation=None, clock=None, sleep=None
) -> tuple[ControlLoop, V4xPcPlant]:
    """Build the loop and its plant (the plant is not opened: :meth:`V4xPcPlant.open`).

    Parameters
    ----------
    s : V4xPcLoopSettings
    link : V4xPcLink
        The board's link.
    observers : iterable
        The loop's observers (:class:`~maglev_ros.loop.ControlLoop`).
    excitation : array_like, shape (N, 4), optional
        Currents added to the command at sample k < N, A.
    clock, sleep : callable, optional
        The plant's clock (default the wall clock).

    Returns
    -------
    (ControlLoop, V4xPcPlant)

    Raises
    ------
    ValueError
        If the set cannot be loaded or controlled, or a setting is out of range.
    """
    from ..control import ControllerConfig, make_controller
    from ..estimation import EstimatorConfig, make_estimator
    from ..physics import linearize

    model = board_model(s.params, s.sensor)
    linear = linearize(model)
    controller = make_controller(
        model,
        ControllerConfig(
            mode='lqr',
            sample_rate=s.sample_rate,
            command_delay=s.command_delay,
            sensor_delay=0,
            coil_dynamics=s.coil_dynamics,
            current_limit=s.current_limit,
            position_scale=s.position_scale,
            current_scale=s.current_scale,
        ),
        linear=linear,
    )
    estimator = make_estimator(
        model,
        EstimatorConfig(
            filter='kf',
            sample_rate=s.sample_rate,
            sensor_delay=0,
            sensor_noise=s.sensor_noise,
            angular_acceleration_noise=s.angular_acceleration_noise,
            bias_states=s.bias_states,
            initial_bias_xy=s.initial_bias_xy,
            measurement='board',
        ),
        linear=linear,
    )
    timing = {k: v for k, v in (('clock', clock), ('sleep', sleep)) if v is not None}
    plant = V4xPcPlant(link, s.scaling, s.current_limit, s.sample_rate, **timing)
    loop = ControlLoop(plant, controller, estimator, excitation=excitation, observers=observers)
    warm_up(loop, V4xPcPlant(link, s.scaling, s.current_limit, s.sample_rate, **timing))
    return loop, plant


class _WarmUpPlant:
    """Stands in for the board while the loop's path runs once (no I/O)."""

    lockstep = True
    n_inputs = 4

    def __init__(self, writer: V4xPcPlant) -> None:
        self.writer = writer  # a plant never opened: its write touches no link

    def write(self, command, stamp_ns: int) -> None:
        self.writer.write(command, stamp_ns)


def warm_up(loop: ControlLoop, spare: V4xPcPlant) -> None:
    """Run the loop's own path once, a missed period and a sample, then reset it.

    Every compiled kernel the loop calls (the estimator's update and its
    predict-only step, the controller, the estimate's round trip through its
    message layout) loads now, not in the first control periods of the run:
    loading them there took 25-31 ms, 25-31 missed periods with the magnet
    uncontrolled. The observers are not called.

    Parameters
    ----------
    loop : ControlLoop
        The loop (its estimator and controller are reset afterwards).
    spare : V4xPcPlant
        A plant of the same settings, never opened: the commands go through its
        guard (no link is touched).
    """
    from .observers import ObserverSet
    from .plant import SampleBlock

    est = loop.estimator
    y = np.vstack([np.full_like(est.y_eq, np.nan), est.y_eq])
    block = SampleBlock(
        index=np.arange(2),
        times=np.arange(2) * 1e-3,
        stamps_ns=np.arange(2, dtype=np.int64) * 1_000_000,
        readings=y,
        currents=np.zeros((2, 4)),
        valid=np.ones(2, dtype=bool),
    )
    plant, observers = loop.plant, loop.observers
    loop.plant, loop.observers = _WarmUpPlant(spare), ObserverSet(())
    try:
        for _ in range(2):
            loop._handle(block, len(block))
    finally:
        loop.plant, loop.observers = plant, observers
        loop.reset()


@dataclass
class V4xPcRun:
    """What :func:`run_v4x_pc_loop` did.

    Attributes
    ----------
    samples : int
        Samples handled.
    reason : str
        Why the loop stopped early ('' if it ran them all).
    round_trip_rate : float
        The board's round trips per second, measured when the plant opened, Hz.
    round_trip_p99 : float
        The 99th percentile of those round trips, s.
    rate_reached : float
        Samples per second over the run, Hz.
    late : int
        Periods started more than half a period late.
    log : SampleLog
        Every sample (for :func:`~maglev_ros.loop.sample_log.write_sample_bag`).
    started, ended : float
        The plant clock at the first sample's request and after the last, s.
    priority_note : str
        Why ``realtime_priority`` was not applied ('' if it was, or was 0).
    settled_from : float
        The plant clock at the first sample of the settling (``started`` when
        there was none), s.
    feedthrough : PairFeedthrough or None
        What the coil pairs left in the readings, measured before the loop
        (None: not measured).
    magnet_wait : float
        s waited for the magnet after that measurement.
    """

    samples: int
    reason: str
    round_trip_rate: float
    round_trip_p99: float
    rate_reached: float
    late: int
    log: object
    started: float
    ended: float
    priority_note: str = ''
    settled_from: float = float('nan')
    feedthrough: object = None
    magnet_wait: float = 0.0


def run_v4x_pc_loop(
    s: V4xPcLoopSettings,
    link,
    samples: int,
    excitation=None,
    clock=None,
    sleep=None,
    progress=None,
    ready=None,
    settle: int = 0,
    notice=None,
) -> V4xPcRun:
    """Open the board, run the closed loop for ``samples`` samples, zero the coils.

    Parameters
    ----------
    s : V4xPcLoopSettings
    link : V4xPcLink
        The board's link (closed).
    samples : int
        Samples to run.
    excitation : CommandExcitation, optional
        Added to the command from the record's first sample (identification),
        faded in over :data:`EXCITATION_RAMP` s.
    clock, sleep : callable, optional
        The plant's clock (default the wall clock).
    progress : callable, optional
        ``progress(done)`` after each second of samples.
    ready : callable, optional
        Called once the loop is built (seconds of model set-up and compiling)
        and before the board is opened: e.g. to start a virtual board, whose
        free magnet falls from the end of its set-up unless the loop runs.
    settle : int, optional
        Samples the loop holds the magnet first, without excitation and not
        logged (the estimator's start and the magnet's first correction are
        not in the record); the excitation and the record start after them.
    notice : callable, optional
        ``notice(text)`` with what the user does next: before the feedthrough
        measurement (the magnet off the board) and after it (place the magnet).

    Returns
    -------
    V4xPcRun

    Raises
    ------
    LinkError
        The board does not answer.
    ValueError
        A setting is out of range, or the board's round trips are too slow.
    """
    import time as _time

    from ..frozen_heap import frozen_heap
    from ..realtime_priority import fifo_priority
    from .sample_log import SampleLog

    ex = None
    if excitation is not None and excitation.enabled:
        from ..control.excitation import ExcitationSchedule

        ex = ExcitationSchedule(excitation, s.sample_rate).sequence(samples)
        ramp = min(len(ex), round(EXCITATION_RAMP * s.sample_rate))
        ex[:ramp] *= np.linspace(0.0, 1.0, ramp)[:, None]  # faded in: no step at the start
        ex = np.concatenate([np.zeros((settle, ex.shape[1])), ex])
    log = SampleLog(first=settle)
    loop, plant = build_v4x_pc_loop(s, link, [log], ex, clock, sleep)
    log.applied_of = plant.applied
    now = clock or _time.monotonic
    if ready is not None:
        ready()
    # no collection of the whole heap stalls the loop; SCHED_FIFO if asked for and allowed
    with frozen_heap(), fifo_priority(s.realtime_priority) as priority_note:
        plant.open()
        try:
            feedthrough, waited = _before_the_magnet(s, loop, link, clock, sleep, notice)
            started = settled_from = now()
            done, chunk, total = 0, max(1, int(s.sample_rate)), settle + samples
            while done < total and not loop.stopped:
                done += loop.run(min(chunk, (settle if done < settle else total) - done))
                if done == settle:
                    started = now()  # the record's start
                if progress is not None and done > settle:
                    progress(done - settle)
            ended = now()
            done = max(0, done - settle)
        finally:
            plant.close()  # 04: the board has no watchdog
    return V4xPcRun(
        done,
        loop.reason,
        plant.round_trip_rate,
        plant.round_trip_p99,
        plant.rate_reached,
        plant.late,
        log,
        started,
        ended,
        priority_note,
        settled_from,
        feedthrough,
        waited,
    )


def _before_the_magnet(s: V4xPcLoopSettings, loop: ControlLoop, link, clock, sleep, notice):
    """Measure the coil pairs' feedthrough, model it, wait for the magnet (if asked to).

    Returns
    -------
    (PairFeedthrough or None, float)
        The measurement and the s waited for the magnet.
    """
    if not s.measure_feedthrough:
        return None, 0.0
    from ..hardware.v4x_pc_feedthrough import (
        measure_feedthrough,
        measurement_time,
        wait_for_magnet,
    )
    from ..physics.board_processing import BoardProcessing

    say = notice or (lambda text: None)
    timing = {'clock': clock, 'sleep': sleep, 'period': 1.0 / s.sample_rate}
    seconds = measurement_time(timing['period'])
    say(f'measuring the coil feedthrough the board leaves ({seconds:.1f} s; the magnet off)')
    feedthrough = measure_feedthrough(link, **timing)
    est = loop.estimator
    est.use_board(BoardProcessing.from_model(est.model, pairs=feedthrough.response))
    say(
        f'{feedthrough.summary()}; now hold the magnet over the centre of the board at its '
        f'height: the loop takes it when its field is there (waiting up to {s.magnet_timeout:g} s)'
    )
    waited = wait_for_magnet(link, float(est.y_eq[2]), timeout=s.magnet_timeout, **timing)
    return feedthrough, waited
