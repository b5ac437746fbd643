"""One control loop for every caller: read, estimate, control, write, observers.

The ros2_control shape (``ros2_control_node``: read, update, write, then wait
for the period): :meth:`ControlLoop.step` reads the samples that came from the
plant, steps the estimator through each, lets the controller answer the newest
(with the excitation added, through the command delay), writes the command and
hands every sample to the observers. A lockstep plant steps one sample per
write, so the loop runs as fast as it computes; a real plant's read waits for
its samples, which paces the loop. The loop does not know which plant,
estimator or controller it runs.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from ..control.config import MAX_COMMAND_DELAY
from ..physics.kernels import odometry_round_trip
from .observers import Observer, ObserverSet
from .plant import Plant, SampleBlock

__all__ = ['ControlLoop', 'LoopSample', 'MAX_COMMAND_DELAY']


@dataclass(frozen=True)
class LoopSample:
    """One sample as the loop handled it (what observers see).

    Attributes
    ----------
    index : int
        Sample number of the run.
    t : float
        Sample time, s.
    stamp_ns : int
        Sample stamp, ns.
    reading : ndarray, shape (3 k,)
        Sensor fields, T.
    currents : ndarray, shape (n_s,)
        Coil currents, A.
    valid : bool
        The reading arrived.
    state : ndarray, shape (12,) or None
        True state (simulated plants).
    estimate : ndarray, shape (12,) or None
        The estimator's state after this sample (None: no estimator or no reading).
    std : ndarray, shape (10,) or None
        Its standard deviations (reduced states).
    nis : float
        NIS of the accepted readings.
    dof : int
        Its degrees of freedom.
    frozen : ndarray of bool, shape (k,) or None
        Sensors the estimator holds frozen.
    command : ndarray, shape (n_s,) or None
        The controller's answer to this sample, A (None: it answered a later
        sample of the same read).
    excitation : ndarray, shape (n_s,) or None
        Excitation added to that command, A.
    applied : ndarray, shape (n_s,) or None
        What was written to the plant after this sample, A (the command
        delay's oldest entry).
    level : str
        The controller's status level ('OK', 'WARN', 'ERROR').
    message : str
        Its status message when the level is not OK.
    """

    index: int
    t: float
    stamp_ns: int
    reading: np.ndarray
    currents: np.ndarray
    valid: bool
    state: np.ndarray | None
    estimate: np.ndarray | None
    std: np.ndarray | None
    nis: float
    dof: int
    frozen: np.ndarray | None
    command: np.ndarray | None
    excitation: np.ndarray | None
    applied: np.ndarray | None
    level: str
    message: str


class ControlLoop:
    """Read, estimate, control, write, observers: the closed loop on any plant.

    Parameters
    ----------
    plant : Plant
        What is read and written (:class:`~maglev_ros.loop.SimulatedPlant`, a board).
    controller : LqrController or PdController
        ``command(t, input, currents)``: with an estimator it is given the
        estimate (as the estimate topic carries it: the LQR), without one the
        raw reading (the PD).
    estimator : Estimator, optional
        Required by the LQR; None with the PD.
    command_delay : int
        Samples a command waits before it is written (a lockstep simulation of
        the board's command latency: the command computed from sample k drives
        the coils from k + delay). 0 for a real plant, whose latency is its own.
    excitation : array_like, shape (N, n_s), optional
        Currents added to the controller's command at sample index k < N, A,
        while the controller is active (identification experiments).
    reference : callable, optional
        ``reference(t) -> position (3,) m or None`` evaluated at each sample; a
        change goes to the controller's ``set_reference``.
    observers : iterable of Observer or (Observer, every)
        Called with each (or each ``every``-th) :class:`LoopSample`, in the
        loop's thread: wrap a slow one in :class:`~maglev_ros.loop.ObserverThread`.
    """

    def __init__(
        self,
        plant: Plant,
        controller,
        estimator=None,
        command_delay: int = 0,
        excitation=None,
        reference: Callable[[float], np.ndarray | None] | None = None,
        observers: Iterable[Observer | tuple[Observer, int]] = (),
    ) -> None:
        from ..control.lqr import LqrController

        if estimator is None and isinstance(controller, LqrController):
            raise ValueError('the LQR needs an estimator')
        self.pd = estimator is None  # the controller reads the raw readings
        if isinstance(command_delay, bool) or command_delay not in range(MAX_COMMAND_DELAY + 1):
            raise ValueError(
                f'command_delay must be an integer from 0 to {MAX_COMMAND_DELAY}, '
                f'got {command_delay!r}'
            )
        self.plant = plant
        self.controller = controller
        self.estimator = estimator
        self.command_delay = command_delay
        self.excitation = None if excitation is None else np.asarray(excitation, dtype=float)
        self.reference = reference
        self.observers = ObserverSet(observers)
        self.stopped = False
        self.reason = ''
        self.reset()

    def reset(self) -> None:
        """Restart the estimator, the controller and the command delay (not the plant)."""
        if self.estimator is not None:
            self.estimator.reset()
        self.controller.reset()
        n_s = self.plant.n_inputs
        self._pending = [np.zeros(n_s) for _ in range(self.command_delay)]  # oldest first
        self._reference = None
        self._level = 'OK'
        self.stopped = False
        self.reason = ''

    def run(self, samples: int, stop: Callable[[], bool] | None = None) -> int:
        """Step until ``samples`` samples were handled, the plant stopped or ``stop()``.

        Parameters
        ----------
        samples : int
            Samples to handle.
        stop : callable, optional
            Polled after every read; True ends the run.

        Returns
        -------
        int
            Samples handled.
        """
        done = 0
        while done < samples and not self.stopped:
            done += self.step(limit=samples - done)
            if stop is not None and stop():
                break
        return done

    def step(self, limit: int | None = None) -> int:
        """One iteration: read, estimate each sample, answer the newest, write, observe.

        Parameters
        ----------
        limit : int, optional
            Handle at most this many of the read's samples (the rest are dropped).

        Returns
        -------
        int
            Samples handled (0 when the plant stopped).
        """
        block = self.plant.read()
        n = len(block) if limit is None else min(len(block), limit)
        if n:
            self._handle(block, n)
        if block.crashed:
            self.stopped = True
            self.reason = block.reason
        return n

    def _handle(self, block: SampleBlock, n: int) -> None:
        est, ctrl = self.estimator, self.controller
        observers = self.observers
        for j in range(n):
            k = int(block.index[j])
            stamp = int(block.stamps_ns[j])
            t = float(block.times[j])
            y = block.readings[j]
            currents = block.currents[j]
            valid = bool(block.valid[j])
            if self.reference is not None:
                self._set_reference(self.reference(t))
            x_hat = std = frozen = None
            nis, dof = 0.0, 0
            last = j == n - 1
            if est is not None and valid:
                x_hat = est.step(y, currents)
                std = est.state_std()
                nis, dof = est.last_nis, est.last_dof
                frozen = est.freeze.frozen.copy()
            command = excitation = applied = None
            if last:
                if self.pd:
                    command = ctrl.command(t, y if valid else None, currents)
                elif x_hat is None:
                    command = ctrl.command(t)
                else:
                    # the controller reads the estimate as the estimate topic carries it
                    command = ctrl.command(t, odometry_round_trip(x_hat), currents)
                total = command
                ex = self.excitation
                if ex is not None and k < len(ex) and ctrl.active:
                    excitation = ex[k]
                    total = command + excitation
                if self.command_delay:
                    self._pending.append(total)
                    applied = self._pending.pop(0)
                else:
                    applied = total
            level, message = self._status()
            if observers:
                state = None if block.states is None else block.states[j]
                # fmt: off
                observers(LoopSample(
                    k, t, stamp, y, currents, valid, state, x_hat, std, nis, dof, frozen,
                    command, excitation, applied, level, message,
                ))
                # fmt: on
            if applied is not None:
                self.plant.write(applied, stamp)

    def _set_reference(self, ref) -> None:
        if ref is not None and (self._reference is None or np.any(ref != self._reference)):
            self._reference = np.array(ref, dtype=float)
            self.controller.set_reference(self._reference)

    def _status(self) -> tuple[str, str]:
        """Return the controller's level and message (asked only while it is not plainly OK)."""
        if self.controller.active and self._level == 'OK':
            return 'OK', ''
        status = self.controller.status()
        self._level = status.level
        return status.level, status.message
