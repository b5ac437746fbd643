"""Input watchdog and enable switch shared by the controllers."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ['ControllerStatus', 'Watchdog']


@dataclass(frozen=True)
class ControllerStatus:
    """Diagnostics snapshot of a controller.

    Attributes
    ----------
    level : {'OK', 'WARN', 'ERROR'}
        ERROR while the input is stale (coils at zero), WARN while disabled,
        re-arming, or the PD sees no magnet.
    message : str
        What is happening and what to do, for people.
    active : bool
        True when the last command came from the control law (not forced to zero).
    timeouts : int
        Times the input went stale since the start.
    saturated : int
        Commands that hit the current limit.
    """

    level: str
    message: str
    active: bool
    timeouts: int
    saturated: int


class Watchdog:
    """Goes *safe* (zero currents) when no input arrived for ``timeout`` seconds.

    Re-arms by itself once ``rearm`` fresh inputs arrived in a row after a
    timeout; the caller then clears its integrators and pending command.

    Parameters
    ----------
    timeout : float
        s without input before going safe.
    rearm : int
        Fresh inputs in a row needed to re-arm.
    """

    def __init__(self, timeout: float, rearm: int):
        self.timeout = float(timeout)
        self.rearm = int(rearm)
        self.reset()

    def reset(self) -> None:
        """Armed, waiting for the first input (the first one arms immediately)."""
        self.last_input: float | None = None
        self.safe = False
        self.fresh = 0
        self.timeouts = 0
        self.reason = ''

    def feed(self, t: float) -> bool:
        """Register an input at time ``t`` (s); return True when armed (may re-arm now).

        Parameters
        ----------
        t : float
            Time of the input, s.
        """
        if self.safe:
            if self.last_input is not None and t - self.last_input > self.timeout:
                self.fresh = 0  # the input stalled again while re-arming
            self.fresh += 1
            self.last_input = t
            if self.fresh >= self.rearm:
                self.safe = False
                self.reason = ''
                return True
            return False
        self.last_input = t
        return True

    def check(self, t: float) -> bool:
        """Return True while armed at time ``t`` (goes safe on a stale input).

        Parameters
        ----------
        t : float
            Now, s.
        """
        if self.safe:
            return False
        if self.last_input is not None and t - self.last_input > self.timeout:
            self.safe = True
            self.fresh = 0
            self.timeouts += 1
            self.reason = (
                f'no input for {1e3 * (t - self.last_input):.1f} ms '
                f'(input_timeout {1e3 * self.timeout:.1f} ms) at t = {t:.4f} s'
            )
            return False
        return True
