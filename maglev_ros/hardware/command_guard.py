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
* **pairs** (V4x PC control, ``pairs=True``): the firmware drives each pair
  antisymmetrically (x+ gets ``p_x``, x- gets ``-p_x``; likewise y), so only
  the pair differences can reach the coils. The command is replaced by its
  nearest antisymmetric one (least squares): ``u_x = (I_x+ - I_x-) / 2`` on
  x+ and ``-u_x`` on x-, likewise y; the common part ``(I_x+ + I_x-) / 2``
  cannot be applied and is dropped (counted in ``common_mode_dropped`` when it
  exceeds one PWM count);
* **scale**: currents become signed PWM counts (:class:`CurrentScaling`),
  at most the scaling's full scale.

The current limit may not exceed the scaling's full scale (the largest
current the PWM can ask for): a larger limit would be capped silently, so it
is refused with an error naming both.

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

__all__ = ['GUARD_COUNTERS', 'CommandGuard', 'GuardDecision', 'pair_differences']

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
    pairs : bool, optional
        The board applies pair differences only (V4x PC control): commands
        are made antisymmetric per pair (module docstring).

    Attributes
    ----------
    counters : dict of str to int
        ``GUARD_COUNTERS``: rejected, clamped and ignored commands, timeouts.

    Raises
    ------
    ValueError
        If the limit or the timeout is not a positive finite number, or the
        limit is above the scaling's full scale.
    """

    def __init__(
        self,
        scaling: CurrentScaling,
        current_limit: float,
        command_timeout: float,
        *,
        enabled: bool = False,
        read_only: bool = False,
        pairs: bool = False,
    ) -> None:
        self.scaling = scaling
        self.read_only = bool(read_only)
        self.pairs = bool(pairs)
        self.counters = dict.fromkeys(GUARD_COUNTERS, 0)
        self.common_mode_dropped = 0
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
            Naming the value that is not a positive finite number, or the
            limit above the scaling's full scale.
        """
        for name, value in (
            ('current_limit', current_limit),
            ('command_timeout', command_timeout),
        ):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f'{name} must be a positive finite number, got {value!r}')
        full = self.scaling.max_current
        if current_limit > full * (1 + 1e-9):
            raise ValueError(
                f"current_limit {current_limit:g} A is above the board's full scale "
                f'{full:.4g} A ({self.scaling.full_scale} PWM counts at '
                f'{self.scaling.counts_per_ampere:.4g} counts/A): commands would be capped '
                'silently; lower current_limit or fix the scaling (supply_voltage, '
                'coil_resistance, counts_per_ampere)'
            )
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
        if self.pairs:
            values, common = _antisymmetric(values)
            if np.any(np.abs(common) * self.scaling.counts_per_ampere > 1.0):
                self.common_mode_dropped += 1
        limit = self.current_limit
        if np.any(np.abs(values) > limit):
            self.counters['commands_clamped'] += 1
            warning = f'clamped command {values.tolist()} A to +-{limit:.3f} A'
            values = np.clip(values, -limit, limit)
        self._last_command_ns = now_ns
        self._timed_out = False
        return GuardDecision(self.scaling.to_counts(values if self._enabled else _ZERO), warning)

    def reject(self, reason: str) -> GuardDecision:
        """Reject a command that could not be read (a malformed message), counted.

        Parameters
        ----------
        reason : str
            What was wrong with it.

        Returns
        -------
        GuardDecision
            Nothing to send, and the warning (``rejected command: REASON``).
        """
        self.counters['commands_rejected'] += 1
        return GuardDecision(None, f'rejected command: {reason}')

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


def _antisymmetric(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest command with x- = -x+ and y- = -y+, and the dropped common parts (A)."""
    u_x, u_y = (values[0] - values[1]) / 2, (values[2] - values[3]) / 2
    common = np.array([(values[0] + values[1]) / 2, (values[2] + values[3]) / 2])
    return np.array([u_x, -u_x, u_y, -u_y]), common


def pair_differences(counts) -> tuple[int, int]:
    """Return the pair differences ``(p_x, p_y)`` of antisymmetric counts (x+, x-, y+, y-).

    Parameters
    ----------
    counts : array_like of int, shape (4,)
        Counts from a pairs guard: ``(p_x, -p_x, p_y, -p_y)``.

    Returns
    -------
    tuple of 2 int
        ``(p_x, p_y)``, the arguments of the ``03`` request.

    Raises
    ------
    ValueError
        If the counts are not antisymmetric per pair.
    """
    c = np.asarray(counts, dtype=np.int64)
    if c.shape != (4,) or c[1] != -c[0] or c[3] != -c[2]:
        raise ValueError(f'counts must be (p_x, -p_x, p_y, -p_y), got {np.ravel(c).tolist()}')
    return int(c[0]), int(c[2])
