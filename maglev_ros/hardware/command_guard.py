"""The command guard: which coil commands reach the board, and as which PWM counts.

A command (4 currents in A, order x+ x- y+ y-) from the graph passes the
guard before the driver writes it to the board (V2x):

* **validate**: not 4 values, or a NaN or infinite value: rejected, nothing
  is sent, the command timeout keeps running;
* **clamp**: values beyond +-``current_limit`` are clamped to it;
* **enable**: while disabled, zero currents are sent whatever is commanded;
  disabling sends zero currents at once;
* **timeout**: when no valid command came for ``command_timeout`` s, zero
  currents are sent (once, until the next valid command);
* **scale**: currents become signed PWM counts (:class:`CurrentScaling`).

A read-only board (V4x firmware: its own controller runs) ignores commands.
Rejections, clamps, ignored commands and timeouts are counted and come with
a warning for the caller to log. The guard does no I/O and reads no clock:
the caller passes the time and writes the counts; it is not thread-safe (the
driver node calls it under one lock).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .scaling import CurrentScaling

__all__ = ['GUARD_COUNTERS', 'CommandGuard', 'GuardDecision']

GUARD_COUNTERS = ('commands_rejected', 'commands_clamped', 'commands_ignored', 'timeouts')
_ZERO = np.zeros(4)


@dataclass(frozen=True)
class GuardDecision:
    """What to do with one command.

    Attributes
    ----------
    counts : ndarray of int64, shape (4,), or None
        PWM counts to send (zeros while disabled), or None: send nothing.
    warning : str
        A problem to log ('' if none): rejected, clamped or ignored.
    """

    counts: np.ndarray | None
    warning: str = ''


class CommandGuard:
    """Validate, clamp, enable, time out and scale coil commands (module docstring).

    Parameters
    ----------
    scaling : CurrentScaling
        Current to PWM counts.
    current_limit : float
        Largest commanded |current|, A (> 0).
    command_timeout : float
        s without a valid command before zero currents are sent (> 0).
    enabled : bool, optional
        Enable state at start.
    read_only : bool, optional
        The board takes no commands (V4x): every command is ignored.

    Attributes
    ----------
    counters : dict of str to int
        ``GUARD_COUNTERS``: rejected, clamped and ignored commands, timeouts.

    Raises
    ------
    ValueError
        If the limit or the timeout is not a positive finite number.
    """

    def __init__(
        self,
        scaling: CurrentScaling,
        current_limit: float,
        command_timeout: float,
        *,
        enabled: bool = False,
        read_only: bool = False,
    ) -> None:
        self.scaling = scaling
        self.read_only = bool(read_only)
        self.counters = dict.fromkeys(GUARD_COUNTERS, 0)
        self._enabled = bool(enabled)
        self._last_command_ns: int | None = None
        self._timed_out = False
        self.configure(current_limit, command_timeout)

    def configure(self, current_limit: float, command_timeout: float) -> None:
        """Set the current limit and the command timeout.

        Parameters
        ----------
        current_limit : float
            Largest commanded |current|, A (> 0).
        command_timeout : float
            s without a valid command before zero currents are sent (> 0).

        Raises
        ------
        ValueError
            Naming the value that is not a positive finite number.
        """
        for name, value in (
            ('current_limit', current_limit),
            ('command_timeout', command_timeout),
        ):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f'{name} must be a positive finite number, got {value!r}')
        self.current_limit = float(current_limit)
        self.command_timeout = float(command_timeout)

    @property
    def enabled(self) -> bool:
        """Whether commands are applied (else zero currents are sent)."""
        return self._enabled

    @property
    def timed_out(self) -> bool:
        """Whether zero currents were sent for lack of commands (until the next one)."""
        return self._timed_out

    @property
    def zero(self) -> np.ndarray:
        """PWM counts of zero currents, shape (4,)."""
        return self.scaling.to_counts(_ZERO)

    def command(self, values, now_ns: int) -> GuardDecision:
        """Pass one command.

        Parameters
        ----------
        values : array_like
            The commanded currents, A (4 expected).
        now_ns : int
            Monotonic time, ns (starts the timeout of a valid command).

        Returns
        -------
        GuardDecision
            Counts to send (None for a rejected or ignored command) and a
            warning, if any.
        """
        if self.read_only:
            self.counters['commands_ignored'] += 1
            return GuardDecision(
                None, 'command ignored: the V4x firmware is read-only (its own controller runs)'
            )
        values = np.asarray(values, dtype=float)
        if values.shape != (4,):
            self.counters['commands_rejected'] += 1
            return GuardDecision(
                None, f'rejected command: need 4 currents (x+, x-, y+, y-), got {values.size}'
            )
        if not np.all(np.isfinite(values)):
            self.counters['commands_rejected'] += 1
            return GuardDecision(
                None, f'rejected command: currents must be finite, got {values.tolist()}'
            )
        warning = ''
        limit = self.current_limit
        if np.any(np.abs(values) > limit):
            self.counters['commands_clamped'] += 1
            warning = f'clamped command {values.tolist()} A to +-{limit:.3f} A'
            values = np.clip(values, -limit, limit)
        self._last_command_ns = now_ns
        self._timed_out = False
        return GuardDecision(self.scaling.to_counts(values if self._enabled else _ZERO), warning)

    def set_enabled(self, enabled: bool) -> np.ndarray | None:
        """Enable or disable the coils.

        Parameters
        ----------
        enabled : bool
            The new state.

        Returns
        -------
        ndarray of int64, shape (4,), or None
            The zero counts to send when disabling, else None.
        """
        self._enabled = bool(enabled)
        return None if self._enabled else self.zero

    def check_timeout(self, now_ns: int) -> float | None:
        """Time the last valid command out.

        Parameters
        ----------
        now_ns : int
            Monotonic time, ns.

        Returns
        -------
        float or None
            The command's age in s when it just timed out (send
            :attr:`zero`), else None (no command yet, already timed out, or
            in time).
        """
        if self._last_command_ns is None or self._timed_out:
            return None
        age = (now_ns - self._last_command_ns) * 1e-9
        if age <= self.command_timeout:
            return None
        self._timed_out = True
        self.counters['timeouts'] += 1
        return age
