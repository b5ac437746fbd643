"""The closed-loop lab session against a board: levitate, settle, excite, record exactly N samples.

The graph of :mod:`~maglev_ros.nodes.closed_loop_lab` with the board
**driver** in place of the simulator, composed in one process
(:mod:`~maglev_ros.nodes.intra_process`): the driver hands each read of the
port to the estimator in its I/O thread, the controller answers at once and
its command goes back to the board through the driver's command guard. The
loop's latency is then one read of the port plus the computation: about
1 ms more than the controller's period, which it is told
(``command_delay`` = :data:`BOARD_COMMAND_DELAY` periods).

The recorder and the identifier take their topics from the taps, deferred
until the read's command is sent
(:class:`~maglev_ros.nodes.intra_process.TapDispatcher`, in the order given).

The board sets the pace and its stamps are not on a grid known in advance
(the board's clock mapped to ROS time: ``hardware.board_clock``), so the
window is chosen on the samples as they come, after the read's command, before
the recorder and the identifier see them (:class:`_SampleWindow`, first on
the ``maglev/sensor_0/field`` tap):

* the settling lasts ``settle`` s of board time from the first sample; the
  controller's excitation starts then;
* the window opens after the first read past ``settle`` +
  :data:`EXCITATION_LEAD_S` (the excitation is on) and holds exactly
  ``samples`` samples. Its bounds are set as the recorder's
  ``record_from``/``record_until`` and the identifier's
  ``identify_from``/``identify_until`` (run-time parameters) half a sample
  period away from the samples, before those nodes get the samples.

There is no true state on a board: the settling and the excursion are those
of the estimate.
"""

from __future__ import annotations

import gc
import os
import struct
import sys
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import numpy as np

from maglev_ros.nodes.closed_loop_lab import (
    BOARD_IDENTIFIER_CHANNELS,
    SETTLE_WINDOW,
    WAIT_S,
    LabGraphSettings,
    LabRun,
    controller_parameters,
    estimator_parameters,
    identifier_parameters,
    online_estimate,
    overrides,
    wait_recorded,
)
from maglev_ros.topics import COMMAND_TOPIC, CURRENTS_TOPIC, EXCITATION_TOPIC, field_topic

__all__ = ['BOARD_COMMAND_DELAY', 'EXCITATION_LEAD_S', 'run_board_closed_loop_lab']

#: Control periods between an estimate and its command's effect on the board: the
#: period itself, and about 1 ms for the read, the link's round trip and the board's
#: next sample (1 period at 1 kHz loses a virtual board's magnet within 2 s).
BOARD_COMMAND_DELAY = 2
#: s after the settling before the window opens: the controller's excitation starts
#: ``settle`` s after its first estimate, which may follow the first sample by a period.
EXCITATION_LEAD_S = 0.002
#: Settled: the estimated position's RMS about the set-point over the settling's last
#: 0.1 s below this on every axis (the simulator's check on the true state takes 0.1 mm;
#: an estimate from 0.1 mT noise wanders about 50 um rms by itself)
SETTLED_RMS_M = 0.2e-3
GIL_SWITCH_S = 0.0005  # s, the interpreter's switch interval during the run
#: s without an estimate before the controller zeroes the coils, and without a command
#: before the driver does: a stall of the loop's thread (another process took the CPU)
#: holds the last command on the board meanwhile; zeroing the coils after a short one
#: loses a magnet the loop would have caught again (a lost one is zeroed at once:
#: the controller's loss distance)
STALE_TIMEOUT_S = 0.1
_STAMP = struct.Struct('<iI')  # a header's stamp, after the 4-byte CDR header


class _SampleWindow:
    """Chooses the recording window on the board's stamps (see the module docstring).

    A listener of the ``maglev/sensor_0/field`` tap, connected before the
    recorder's and the identifier's: it sets their window before they take
    the read that opens or closes it.

    Parameters
    ----------
    settle_ns : int
        Board time from the first sample to the window's opening, ns.
    samples : int
        Samples in the window.
    period_ns : int
        Sample period, ns.
    set_window : callable
        ``set_window(first_s, last_s)``: the window's bounds (s of ROS time;
        ``last_s`` 0: no end yet), set on the recorder and the identifier:
        at the first read, not before the settling's end; then exactly.
    """

    def __init__(
        self,
        settle_ns: int,
        samples: int,
        period_ns: int,
        set_window: Callable[[float, float], None],
    ) -> None:
        self._settle_ns = settle_ns
        self._samples = samples
        self._half = period_ns // 2
        self._set_window = set_window
        self.first_ns: int | None = None  # the first sample's stamp
        self.start_ns: int | None = None  # the window's first bound (between samples)
        self.end_ns: int | None = None
        self.recorded = 0  # samples in the window so far
        self.opened_at: float | None = None  # time.monotonic() at the opening
        self.error: Exception | None = None

    def on_fields(self, messages: list) -> None:
        """Count a read's samples; open, then close the window (the driver's thread)."""
        stamps = [sec * 1_000_000_000 + nsec for sec, nsec in map(self._stamp, messages)]
        if not stamps or self.end_ns is not None:
            return
        if self.first_ns is None:
            self.first_ns = stamps[0]
            # not before the settling's end: the commands until then are held, and the
            # one in force at the window's start is logged at it (the recorder's rule)
            self._apply((self.first_ns + self._settle_ns) * 1e-9, 0.0)
        if self.start_ns is None:
            if stamps[-1] - self.first_ns >= self._settle_ns:
                self.start_ns = stamps[-1] + self._half  # the next read's samples on
                self.opened_at = time.monotonic()
                self._apply(self.start_ns * 1e-9, 0.0)
            return
        left = self._samples - self.recorded
        if len(stamps) < left:
            self.recorded += len(stamps)
            return
        self.recorded = self._samples
        self.end_ns = stamps[left - 1] + self._half
        self._apply(self.start_ns * 1e-9, self.end_ns * 1e-9)

    @staticmethod
    def _stamp(raw: bytes) -> tuple[int, int]:
        return _STAMP.unpack_from(raw, 4)

    def _apply(self, first_s: float, last_s: float) -> None:
        try:
            self._set_window(first_s, last_s)
        except Exception as err:  # noqa: BLE001 - reported by the lab's thread
            self.error = err


class _EstimateLog:
    """The estimated positions (m) and their stamps, from the estimator's channel."""

    def __init__(self) -> None:
        self.stamps: list[int] = []
        self.positions: list[np.ndarray] = []

    def on_estimate(self, stamp: int, x: np.ndarray) -> None:
        self.stamps.append(stamp)
        self.positions.append(x[:3].copy())

    def between(self, first_ns: int, last_ns: int) -> np.ndarray:
        """Positions stamped in ``[first_ns, last_ns]``, shape (n, 3)."""
        n = min(len(self.stamps), len(self.positions))  # the driver's thread may append
        stamps = np.asarray(self.stamps[:n], dtype=np.int64)
        keep = (stamps >= first_ns) & (stamps <= last_ns)
        return np.asarray(self.positions[:n])[keep] if keep.any() else np.empty((0, 3))


def run_board_closed_loop_lab(
    settings: LabGraphSettings,
    bag: Path,
    port: str,
    n_sensors: int,
    stop=None,
    progress: Callable[[str, int, int], None] | None = None,
) -> LabRun:
    """Run the closed-loop lab session on the board at ``port`` and record the bag.

    Parameters
    ----------
    settings : LabGraphSettings
        What to run (``realtime``, ``control_rate``; the simulator's settings
        other than the sensor delay and the coil dynamics are not used).
    bag : Path
        Bag directory to create.
    port : str
        The board's serial device.
    n_sensors : int
        Sensors per board record.
    stop : StopSignals or threading.Event, optional
        Ends the run when a stop signal arrives.
    progress : callable, optional
        ``progress(stage, done, total)``: ``settling`` (ms of board time) and
        ``recording`` (samples).

    Returns
    -------
    LabRun
        ``positions``: the estimated positions over the window; ``settle_rms``
        and ``settled``: of the estimate.

    Raises
    ------
    KeyboardInterrupt
        On a stop signal (the bag is finalised first, the coils zeroed).
    RuntimeError
        If the board sends no samples or the window cannot be set (names what).
    """
    from maglev_ros.nodes import intra_process
    from maglev_ros.nodes.bringup import Bringup
    from maglev_ros.nodes.controller import ControllerNode
    from maglev_ros.nodes.driver import DriverNode
    from maglev_ros.nodes.estimator import EstimatorNode
    from maglev_ros.nodes.identifier import IdentifierNode
    from maglev_ros.nodes.recorder import RecorderNode
    from maglev_ros.physics import make_model
    from maglev_ros.physics.equilibria import find_equilibria
    from maglev_ros.sysid.online import load_kernels

    load_kernels()  # the identifier's, before the loop closes: 0.3-1.5 s holding the GIL
    s = settings
    period_ns = round(1e9 / s.sample_rate)
    settle_ns = round((s.settle + EXCITATION_LEAD_S) * 1e9)
    z_eq = find_equilibria(make_model(s.params))[0].z
    topics = [
        *(field_topic(k) for k in s.sensors),
        CURRENTS_TOPIC,
        COMMAND_TOPIC,
        EXCITATION_TOPIC,
    ]
    report = progress or (lambda stage, done, total: None)
    nothing = dict(first=0.0, last=1e-9)  # a window of 1 ns at t = 0: nothing
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with Bringup() as lab, ExitStack() as cleanup:
        ctx = lab.context
        # recording and identifying after the command is sent (a board waits for nobody)
        dispatcher = intra_process.TapDispatcher()
        intra_process.dispatch_taps(ctx, dispatcher)
        cleanup.callback(dispatcher.close)  # hands on what is queued (last: LIFO)
        cleanup.callback(intra_process.dispatch_taps, ctx, None)
        driver = lab.add(
            DriverNode(
                open_port=False,  # once every node is up (start below)
                context=ctx,
                parameter_overrides=overrides(
                    port=port,
                    n_sensors=n_sensors,
                    start_enabled=True,
                    command_timeout=STALE_TIMEOUT_S,
                    confirm_records=False,  # latency: every record handed on at once
                    intra_process=True,
                ),
            )
        )
        cleanup.callback(driver.close)  # the loop stops (coils at zero), then the taps' queue
        est = lab.add(
            EstimatorNode(
                context=ctx,
                parameter_overrides=overrides(
                    **estimator_parameters(s, publish_rate=s.control_rate, intra_process=True)
                ),
            )
        )
        ctrl = lab.add(
            ControllerNode(
                context=ctx,
                parameter_overrides=overrides(
                    **controller_parameters(
                        s,
                        replace(s.control_excitation, start=s.settle),
                        delay_commands=False,
                        sample_rate=s.control_rate,
                        trigger='estimate',
                        intra_process=True,
                        command_delay=BOARD_COMMAND_DELAY,
                        input_timeout=STALE_TIMEOUT_S,
                    )
                ),
            )
        )
        estimates = _EstimateLog()
        if est.estimates is None or driver.samples_source.listeners == 0:
            raise RuntimeError('the estimator did not connect to the driver in this process')
        est.estimates.connect(estimates.on_estimate, 'maglev_lab_estimates')
        cleanup.callback(est.estimates.disconnect, estimates.on_estimate)
        ident = recorder = None

        def set_window(first_s: float, last_s: float) -> None:
            for node, values in (
                (ident, dict(identify_from=first_s, identify_until=last_s)),
                (recorder, dict(record_from=first_s, record_until=last_s)),
            ):
                result = node.set_parameters_atomically(overrides(**values))
                if not result.successful:
                    raise RuntimeError(f'{node.get_name()}: {result.reason}')

        window = _SampleWindow(settle_ns, s.samples, period_ns, set_window)
        # first on the tap: the window is set before the identifier and the recorder
        # (created next) take the read that opens or closes it
        fields_tap = intra_process.tap(ctx, driver.resolve_topic_name(field_topic(0)))
        fields_tap.connect(window.on_fields, 'maglev_lab_window')
        cleanup.callback(fields_tap.disconnect, window.on_fields)
        ident = lab.add(
            IdentifierNode(
                context=ctx,
                parameter_overrides=overrides(
                    **identifier_parameters(
                        s,
                        BOARD_IDENTIFIER_CHANNELS,
                        trigger=field_topic(0),  # the currents: the same stamps
                        identify_from=nothing['first'],
                        identify_until=nothing['last'],
                    )
                ),
            )
        )
        recorder = lab.add(
            RecorderNode(
                context=ctx,
                parameter_overrides=overrides(
                    path=str(bag),
                    storage=s.storage,
                    topics=topics,
                    log_clock='stamp',
                    metadata_node=driver.get_name(),
                    record_from=nothing['first'],
                    record_until=nothing['last'],
                ),
            ),
            destroy_last=True,  # finalises the bag once the others are gone
        )
        lab.start()
        gc.freeze()  # start-up's objects stay out of the collector's way (a 0.1 s stall)
        driver.start()  # the board's first sample now finds the whole loop
        # a thread holding the GIL hands it over after this long (default 5 ms): the
        # executor's work (the identifier's model, diagnostics) delays the loop less
        cleanup.callback(sys.setswitchinterval, sys.getswitchinterval())
        sys.setswitchinterval(GIL_SWITCH_S)
        return _run(lab, s, window, estimates, driver, ctrl, ident, recorder, topics, z_eq,
                    report, stop)  # fmt: skip


def _run(lab, s, window, estimates, driver, ctrl, ident, recorder, topics, z_eq, report, stop):
    """Wait for the settling and the window; return the run's figures."""
    settle_ms = round(s.settle * 1e3)
    last = [-1, time.monotonic()]

    def progressing() -> None:
        """Raise if the window could not be set or the board's records stopped."""
        if window.error is not None:
            raise RuntimeError(f'the recording window could not be set: {window.error}')
        now, done = time.monotonic(), driver.counters['records']
        if done != last[0]:
            last[:] = [done, now]
        elif now - last[1] > WAIT_S:
            raise RuntimeError(
                f'no sample from the board for {WAIT_S:g} s (link {driver.link_state})'
            )

    def settled() -> bool:
        progressing()
        first, newest = window.first_ns, estimates.stamps[-1] if estimates.stamps else None
        done = 0 if first is None or newest is None else (newest - first) // 1_000_000
        report('settling', int(min(max(done, 0), settle_ms)), settle_ms)
        return window.start_ns is not None

    def recorded() -> bool:
        progressing()
        report('recording', window.recorded, s.samples)
        return window.end_ns is not None

    lab.wait_until(settled, 'the settling', timeout=1e9, stop=stop)
    lab.wait_until(recorded, f'the recording ({s.samples} samples)', timeout=1e9, stop=stop)
    wall = time.monotonic() - window.opened_at
    per_sample = [t for t in topics if t not in (COMMAND_TOPIC, EXCITATION_TOPIC)]
    wait_recorded(lab, recorder, ident, per_sample, s.samples, stop)
    equilibrium = np.array([0.0, 0.0, z_eq])
    start, end = window.start_ns, window.end_ns
    before = estimates.between(start - round(SETTLE_WINDOW * 1e9), start) - equilibrium
    rms = np.sqrt(np.mean(before**2, axis=0)) if len(before) else np.full(3, np.nan)
    status = ctrl.controller.status()
    lost = status.level == 'ERROR'  # the magnet lost, or no estimates: coils at zero
    return LabRun(
        samples=int(s.samples),
        settle_s=s.settle,
        settle_rms=rms,
        settled=bool(np.all(rms < SETTLED_RMS_M)),
        simulated_s=(end - window.first_ns) * 1e-9,
        wall_s=wall,
        timeouts=int(driver.counters['timeouts']),
        crashed=bool(lost),
        crash_reason=status.message if lost else '',
        controller={
            'level': status.level,
            'message': status.message,
            'saturated': int(status.saturated),
            'commands': int(ctrl.commands),
        },
        identifier=online_estimate(ident, s.sample_rate),
        positions=estimates.between(start, end),
    )
