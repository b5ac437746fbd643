"""The controller as a stage of its own: inputs by stamp in, one command per sample out.

The controller node (``ros2 run maglev_ros controller``, separate processes)
and the lockstep lab graphs run the control law on messages that arrive one
by one, in any order. :class:`Commander` is that stage without ROS: it pairs
each sample's parts by stamp (:class:`~maglev_ros.loop.sample_assembly.SampleAssembler`),
asks the controller for the command, adds the excitation of the sample's
index, delays it by a sample when asked (a lockstep graph with the board's
timing), and says when its status changed. The node decodes a message, makes
one call and publishes what comes back.

Two ways in (``trigger``):

* ``sample`` (lockstep): a sample is its currents and its estimate (LQR), or
  every sensor's field and the currents (PD); exactly one command per sample,
  in stamp order;
* ``estimate`` (real time): one command per estimate, with its own stamp.
  When the estimates stop, :meth:`Commander.check_stale` commands zero
  currents once; before the first one, it commands zero currents every
  period once an estimator has been heard for ``ready_after`` s (a simulator
  that waits for its controller then starts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..control.excitation import CommandExcitation, ExcitationSchedule
from ..topics import BASE_FRAME, REFERENCE_TOPIC
from .sample_assembly import SampleAssembler

__all__ = ['READY_AFTER_S', 'TRIGGERS', 'Command', 'Commander', 'check_trigger']

#: What a command answers: each sample, or each estimate.
TRIGGERS = ('sample', 'estimate')
#: s an estimator must have been heard before zero commands precede its first estimate.
READY_AFTER_S = 0.5


def check_trigger(trigger: str, mode: str) -> None:
    """Raise ValueError unless ``trigger`` is one of :data:`TRIGGERS` and fits ``mode``.

    Parameters
    ----------
    trigger : str
        What a command answers.
    mode : str
        The controller's mode (``estimate`` needs ``lqr``).
    """
    if trigger not in TRIGGERS:
        raise ValueError(f'trigger must be one of {", ".join(TRIGGERS)}, got {trigger!r}')
    if trigger == 'estimate' and mode != 'lqr':
        raise ValueError(
            f"trigger 'estimate' needs mode 'lqr' (the PD reads the fields), got {mode!r}"
        )


@dataclass(frozen=True)
class Command:
    """One command to publish.

    Attributes
    ----------
    stamp_ns : int
        Stamp of the sample it answers, ns.
    total : ndarray, shape (n_s,)
        Coil currents, A (the excitation included).
    excitation : ndarray, shape (n_s,) or None
        The excitation part, A (None: the controller has no excitation).
    status_changed : bool
        The controller's level changed with this command (report it now).
    """

    stamp_ns: int
    total: np.ndarray
    excitation: np.ndarray | None
    status_changed: bool = False


class Commander:
    """The control law on stamped inputs (see the module docstring).

    Parameters
    ----------
    controller : LqrController or PdController
        The control law (:func:`~maglev_ros.control.make_controller`).
    n_sensors : int
        Sensors of the PD's sample.
    trigger : {'sample', 'estimate'}
        What a command answers.
    excitation : CommandExcitation
        Added to every command while the controller is active (``signal``
        ``none``: off).
    delay_commands : bool
        Publish for sample k the command computed at k - 1.
    ready_after : float
        ``trigger: estimate``: s an estimator must have been heard before
        zero commands go out ahead of its first estimate.
    """

    def __init__(
        self,
        controller,
        n_sensors: int,
        trigger: str = 'sample',
        excitation: CommandExcitation | None = None,
        delay_commands: bool = False,
        ready_after: float = READY_AFTER_S,
    ) -> None:
        self.controller = c = controller
        self.lqr = c.config.mode == 'lqr'
        check_trigger(trigger, c.config.mode)
        self.trigger = trigger
        self.n_sensors = n_sensors
        self.n_inputs = n = c.n_inputs
        self.rate = c.config.sample_rate
        self.timeout = c.config.input_timeout
        self.schedule = ExcitationSchedule(excitation or CommandExcitation(), self.rate)
        self.delay_commands = delay_commands
        self.ready_after = ready_after
        self.currents_part = 0 if self.lqr else n_sensors
        self._samples = SampleAssembler(
            2 if self.lqr else n_sensors + 1, round(self.timeout * 1e9)
        )
        self._pending = (np.zeros(n), np.zeros(n))  # delay_commands: (total, excitation)
        self._first_stamp: int | None = None
        self._status_key: tuple | None = None
        self._level = 'OK'
        self.commands = 0
        self.last_command = np.zeros(n)
        self.last_excitation = np.zeros(n)
        self.last_estimate_s: float | None = None  # monotonic s of the last estimate
        self.heard_since: float | None = None  # monotonic s an estimator was heard from
        self.estimates_seen = False
        self.last_input_ns: int | None = None  # node clock at the last input message
        if self.lqr:  # its compiled law loads now (~10 ms), not on the first estimate
            enabled, c.enabled = c.enabled, True
            c.command(0.0, np.array(c.x_eq, dtype=float))
            c.enabled = enabled
            c.reset()

    @property
    def excited(self) -> bool:
        """Whether an excitation is added (and published apart)."""
        return self.schedule.enabled

    # ------------------------------------------------------------------ inputs
    def sample_part(self, part: int, stamp_ns: int, values) -> list[Command]:
        """Take one part of a sample (``trigger: sample``); return the commands it releases.

        Parameters
        ----------
        part : int
            LQR: 0 the currents, 1 the estimate (shape (12,)); PD: sensor k's
            field (3,) for k < n_sensors, then the currents (n_s,).
        stamp_ns : int
            The sample's stamp, ns.
        values : array_like
            The part's values (SI units).

        Returns
        -------
        list of Command
            One per released sample, in stamp order.
        """
        return [self._answer(s) for s in self._samples.add(part, stamp_ns, values)]

    def estimate(self, stamp_ns: int, x: np.ndarray, now_s: float) -> Command:
        """Answer one estimate (``trigger: estimate``).

        Parameters
        ----------
        stamp_ns : int
            The estimate's stamp, ns.
        x : ndarray, shape (12,)
            The estimated state (as the estimate topic carries it).
        now_s : float
            Monotonic time of its arrival, s (the stale check's clock).
        """
        self.last_estimate_s = now_s
        self.estimates_seen = True
        return self._send(stamp_ns, self.controller.command(stamp_ns * 1e-9, x))

    def check_stale(self, now_s: float, estimator_heard: bool) -> Command | None:
        """``trigger: estimate``: the command a silence calls for, if any.

        Parameters
        ----------
        now_s : float
            Monotonic time, s.
        estimator_heard : bool
            An estimator's publisher is matched to the estimate input.

        Returns
        -------
        Command or None
            Zero currents ahead of the first estimate (once heard for
            ``ready_after``), the core's answer to a missing input once per
            silence of ``input_timeout``, else None.
        """
        if self.last_estimate_s is None:
            if not estimator_heard:
                self.heard_since = None
            elif self.heard_since is None:
                self.heard_since = now_s
            ready = self.heard_since is not None and now_s - self.heard_since >= self.ready_after
            if not self.estimates_seen and ready:
                return self._publishable(0, np.zeros(self.n_inputs), None)
            return None
        if now_s - self.last_estimate_s > self.timeout:
            self.last_estimate_s = None  # one zero command per silence
            last_t = self.controller.watchdog.last_input or 0.0
            return self._publishable(0, self.controller.command(last_t + 2 * self.timeout), None)
        return None

    def set_reference(self, frame: str, position) -> tuple[bool, str]:
        """Move the LQR's set-point; return whether it was taken and what to log.

        Parameters
        ----------
        frame : str
            The reference's frame (``maglev_base`` or empty).
        position : sequence of float, shape (3,)
            x, y, z, m.
        """
        if not self.lqr:
            return False, f'{REFERENCE_TOPIC} ignored: the PD holds the equilibrium'
        if frame not in ('', BASE_FRAME):
            return False, f'{REFERENCE_TOPIC} refused: frame {frame!r}, expected {BASE_FRAME!r}'
        try:
            self.controller.set_reference(list(position))
        except ValueError as err:
            return False, f'{REFERENCE_TOPIC} refused: {err}'
        return True, 'reference ' + ' '.join(f'{v:.6g}' for v in position) + ' m'

    def enable(self, on: bool) -> str:
        """Switch the controller; return from which command on the new state holds.

        Commands are numbered from 0 in publishing order (:attr:`commands`):
        ``... from command N on`` means command N and every later one follow
        the new state, all zero after a disable (a command held back by
        ``delay_commands`` included). Earlier ones may still be in flight.

        Parameters
        ----------
        on : bool
            Enable (True) or command zero currents (False).
        """
        self.controller.set_enabled(on)
        if not on:
            self._pending = (np.zeros(self.n_inputs), np.zeros(self.n_inputs))
        state = 'enabled' if on else 'disabled: zero currents'
        return f'{state} from command {self.commands} on'

    # ------------------------------------------------------------------ commands
    def _answer(self, sample) -> Command:
        t = sample.stamp * 1e-9
        parts = sample.parts
        ctrl = self.controller
        if self.lqr:
            currents, x = parts
            command = ctrl.command(t) if x is None else ctrl.command(t, x, currents)
        else:
            fields_, currents = parts[:-1], parts[-1]
            y = None
            if any(f is not None for f in fields_):
                y = np.full(3 * self.n_sensors, np.nan)
                for k, f in enumerate(fields_):
                    if f is not None:
                        y[3 * k : 3 * k + 3] = f
            command = ctrl.command(t, y, currents)
        return self._send(sample.stamp, command)

    def _send(self, stamp: int, command: np.ndarray) -> Command:
        if not self.excited:
            return self._publishable(stamp, command, None)
        if self._first_stamp is None:
            self._first_stamp = stamp
        excitation = np.zeros(self.n_inputs)
        if self.controller.active:
            excitation = self.schedule.value(round((stamp - self._first_stamp) * self.rate * 1e-9))
        return self._publishable(stamp, command + excitation, excitation)

    def _publishable(self, stamp: int, total: np.ndarray, excitation) -> Command:
        if self.excited and excitation is None:  # a zero command of the safety or ready checks
            excitation = np.zeros(self.n_inputs)
        if self.delay_commands:  # sample k gets the command computed at k - 1
            (total, excitation), self._pending = self._pending, (total, excitation)
            if self.excited and excitation is None:
                excitation = np.zeros(self.n_inputs)
        self.last_command = total
        if excitation is not None:
            self.last_excitation = excitation
        self.commands += 1
        return Command(stamp, total, excitation if self.excited else None, self._status_moved())

    def _status_moved(self) -> bool:
        """Whether the controller's level changed (status() asked only when it may have)."""
        c = self.controller
        key = (
            getattr(c, 'lost', None),
            getattr(c, 'magnet_present', None),
            c.watchdog.safe,
            c.enabled,
            c.active,
        )
        if key == self._status_key:
            return False
        self._status_key = key
        level = c.status().level
        moved, self._level = level != self._level, level
        return moved

    def heard(self, now_ns: int) -> None:
        """Note that an input message arrived.

        Parameters
        ----------
        now_ns : int
            The node's clock, ns.
        """
        self.last_input_ns = now_ns

    def describe(self) -> str:
        """Return one line: rate, limit, timeout, state, trigger, excitation."""
        c = self.controller.config
        return (
            f'{c.sample_rate:g} Hz, limit {c.current_limit:g} A, input timeout '
            f'{1e3 * c.input_timeout:g} ms, {"enabled" if self.controller.enabled else "disabled"}'
            f', trigger {self.trigger}, {self.schedule.config.describe()}'
        )

    def diagnostic(self, now_ns: int, period: float) -> tuple[int, str, dict[str, object]]:
        """Return the diagnostic level (0 OK, 1 WARN, 2 ERROR), message and values.

        A graph that stopped (no input message for ``input_timeout`` and two
        ``period``) is an ERROR whatever the controller says: no command is sent.

        Parameters
        ----------
        now_ns : int
            The node's clock, ns.
        period : float
            The diagnostics' period, s.
        """
        s = self.controller.status()
        level, message = {'OK': 0, 'WARN': 1}.get(s.level, 2), s.message
        last = self.last_input_ns
        if last is not None and now_ns - last > max(self.timeout, 2 * period) * 1e9:
            level = 2
            message = (
                f'no sample for {(now_ns - last) * 1e-9:.2f} s: no commands sent '
                "(the driver's command_timeout zeroes the coils)"
            )
        return level, message, self.diagnostic_values()

    def diagnostic_values(self) -> dict[str, object]:
        """Return the diagnostics' values: mode, state, counts, last command, reference."""
        c = self.controller
        s = c.status()
        values = {
            'mode': c.config.mode,
            'enabled': str(c.enabled).lower(),
            'active': str(s.active).lower(),
            'commands': self.commands,
            'last command (A)': ' '.join(f'{v:.6g}' for v in self.last_command),
            'timeouts': s.timeouts,
            'saturated commands': s.saturated,
        }
        if self.excited:
            values['excitation'] = self.schedule.config.describe()
            values['last excitation (A)'] = ' '.join(f'{v:.6g}' for v in self.last_excitation)
        if self.lqr:
            values['reference (m)'] = ' '.join(f'{v:.6g}' for v in c.reference)
        return values
