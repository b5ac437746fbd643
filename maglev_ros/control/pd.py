"""The board firmware's PD on the raw field: Bx drives the x coils, By the y coils."""

from __future__ import annotations

import math

import numpy as np

from ..physics import linearize
from .config import ControllerConfig
from .safety import ControllerStatus, Watchdog

__all__ = ['PdController']


class PdController:
    """PD on one sensor's horizontal field, for comparison with the LQR.

    ``e = (Bx, By) - (Bx, By)_eq`` (after removing the coils' direct field
    ``D i`` when ``pd_feedthrough``), low-passed at ``pd_cutoff``; the
    derivative is that of the filtered field, low-passed once more at the
    same cut-off (the difference of a filtered noisy field is still white).
    ``g = kp e + kd de/dt`` and the coil pairs are driven antisymmetrically:
    ``x+ = -g_x, x- = +g_x`` (a positive x+ current pushes the magnet to +x,
    and Bx grows with x), the same for y. Active only while
    ``|Bz - Bz_base|`` (Bz_base: the field without the magnet) exceeds
    ``magnet_threshold``; z and the tilts are left to the permanent magnets,
    as on the board.

    Parameters
    ----------
    model : MaggyModel
    config : ControllerConfig, optional
    linear : LinearModel, optional
        Linearisation about the equilibrium (for D and the equilibrium field).
    """

    def __init__(self, model, config: ControllerConfig | None = None, linear=None):
        self.config = config or ControllerConfig(mode='pd')
        c = self.config
        lin = linear if linear is not None else linearize(model)
        n_sensors = model.n_outputs // 3
        if c.pd_sensor >= n_sensors:
            raise ValueError(f'pd_sensor {c.pd_sensor} does not exist (the set has {n_sensors})')
        rows = slice(3 * c.pd_sensor, 3 * c.pd_sensor + 3)
        self.D = np.array(lin.D[rows], dtype=float)
        self.y_eq = np.array(lin.y_eq[rows], dtype=float)
        no_magnet = model.measurement(lin.x_eq, None, with_magnet=False)
        self.bz_base = float(no_magnet[3 * c.pd_sensor + 2])
        self.rows = rows
        self.n_inputs = model.n_inputs
        if self.n_inputs != 4:
            raise ValueError(
                f'the PD drives 4 coils (x+, x-, y+, y-), the set has {self.n_inputs}'
            )
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * c.pd_cutoff * c.dt)
        self.limit = c.current_limit
        self.watchdog = Watchdog(c.input_timeout, c.rearm_samples)
        self.enabled = True
        self.reset()

    def reset(self) -> None:
        """Clear the filters and the watchdog."""
        self.watchdog.reset()
        self._filtered = None
        self._rate = np.zeros(2)
        self._prev_currents = None
        self.magnet_present = False
        self.saturated = 0
        self.active = False
        self.last_command = np.zeros(self.n_inputs)

    def set_enabled(self, enabled: bool) -> None:
        """Enable or disable (disabled: zero currents).

        Parameters
        ----------
        enabled : bool
        """
        self.enabled = bool(enabled)

    def command(self, t: float, y=None, currents=None) -> np.ndarray:
        """Return the coil command for the sample at ``t`` from its raw readings.

        Parameters
        ----------
        t : float
            s.
        y : array_like, shape (3 k,), optional
            The sample's readings, T (None when no sample arrived).
        currents : array_like, shape (4,), optional
            The sample's measured currents, A.

        Returns
        -------
        ndarray, shape (4,)
            A.
        """
        c = self.config
        if y is None:
            if not self.watchdog.check(t) or not self.enabled:
                return self._zero()
            return self.last_command.copy()
        if not self.watchdog.feed(t) or not self.enabled:
            return self._zero()
        b = np.asarray(y, dtype=float)[self.rows]
        cur = np.zeros(self.n_inputs) if currents is None else np.asarray(currents, dtype=float)
        seen = cur if c.sensor_delay == 0 or self._prev_currents is None else self._prev_currents
        self._prev_currents = cur
        if c.pd_feedthrough:
            b = b - self.D @ seen
        self.magnet_present = abs(b[2] - self.bz_base) > c.magnet_threshold
        if not self.magnet_present or not np.all(np.isfinite(b)):
            self._filtered = None
            return self._zero()
        e = b[:2] - self.y_eq[:2]
        if self._filtered is None:
            self._filtered = e.copy()
            self._rate = np.zeros(2)
        else:
            previous = self._filtered.copy()
            self._filtered += self.alpha * (e - self._filtered)
            self._rate += self.alpha * ((self._filtered - previous) / c.dt - self._rate)
        g = c.pd_kp * self._filtered + c.pd_kd * self._rate
        cmd = np.array([-g[0], g[0], -g[1], g[1]])
        clipped = np.clip(cmd, -self.limit, self.limit)
        if np.any(clipped != cmd):
            self.saturated += 1
        self.last_command = clipped
        self.active = True
        return clipped.copy()

    def _zero(self) -> np.ndarray:
        self.last_command = np.zeros(self.n_inputs)
        self.active = False
        return np.zeros(self.n_inputs)

    def status(self) -> ControllerStatus:
        """Level and message for the diagnostics."""
        w = self.watchdog
        if w.safe:
            level, message = 'ERROR', f'input stale: {w.reason}; coils at zero current'
        elif not self.enabled:
            level, message = 'WARN', 'disabled: coils at zero current (enable to levitate)'
        elif not self.magnet_present:
            level, message = 'WARN', 'no magnet over the sensor: coils at zero current'
        else:
            level, message = 'OK', 'levitating (PD on the raw field)'
        return ControllerStatus(level, message, self.active, w.timeouts, self.saturated)
