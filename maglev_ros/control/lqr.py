"""LQR state feedback on the estimate, with current limit, anti-windup and a set-point."""

from __future__ import annotations

import math

import numpy as np

from ..physics import linearize
from ..physics.linearization import REDUCED_STATES
from .config import ControllerConfig
from .design import design_lqr, steady_state
from .kernels import lqr_law
from .safety import ControllerStatus, Watchdog

__all__ = ['LqrController']


class LqrController:
    """State feedback ``c = c_ss - K (xi - xi_ss)`` on the estimated state.

    Parameters
    ----------
    model : MaggyModel
        The model the design believes (its parameter set's coil L / R sets
        the coils' lag).
    config : ControllerConfig, optional
        ``mode`` is ignored (this is the LQR).
    linear : LinearModel, optional
        Linearisation about the equilibrium (computed if not given).

    Notes
    -----
    The set-point (:meth:`set_reference`) is a position; the steady state that
    holds it, ``A dx + B u = 0``, gives the feedforward currents ``u_ss``.
    Commands are clipped at ``current_limit``; with integral action the
    integrators hold while any coil is clipped (conditional integration).
    An estimate farther than ``loss_distance`` from the equilibrium latches
    *lost*: zero currents and an ERROR until :meth:`set_enabled` (True) or
    :meth:`reset`.
    """

    def __init__(self, model, config: ControllerConfig | None = None, linear=None):
        self.config = config or ControllerConfig()
        lin = linear if linear is not None else linearize(model)
        self.linear = lin.reduced() if lin.A.shape[0] == 12 else lin
        coils = model.params.coils
        tau = coils.inductance / coils.resistance if self.config.coil_dynamics else 0.0
        self.design = design_lqr(self.linear, self.config, tau)
        if not self.design.stable:
            raise ValueError('the LQR design is not stabilising; check the weights')
        self.x_eq = np.array(self.linear.x_eq, dtype=float)
        self.reduced = np.array(REDUCED_STATES)
        self.n_inputs = self.linear.B.shape[1]
        self.limit = self.config.current_limit
        self.watchdog = Watchdog(self.config.input_timeout, self.config.rearm_samples)
        self.enabled = True
        # the gain split per part of xi, on the full 12-state (gamma, wz: zero columns)
        K = self.design.K
        layout = self.design.layout
        m = self.n_inputs
        self._Kx = np.zeros((m, 12))
        self._Kx[:, self.reduced] = K[:, layout['dx']]
        self._Ki = np.ascontiguousarray(K[:, layout['i']]) if 'i' in layout else np.zeros((m, m))
        # the pending commands, newest first (command_delay N: N of them; none: one zero)
        self._n_pending = max(self.config.command_delay, 1)
        self._Kc = (
            np.ascontiguousarray(K[:, layout['c_prev']])
            if 'c_prev' in layout
            else np.zeros((m, m))
        )
        self._Ke = np.ascontiguousarray(K[:, layout['e']]) if 'e' in layout else np.zeros((m, 3))
        self._has_i = 'i' in layout
        self._has_e = 'e' in layout
        self.set_reference(None)
        self.reset()

    def reset(self) -> None:
        """Clear the integrators, the pending command and the watchdog."""
        self.watchdog.reset()
        self._c_prev = np.zeros(self._n_pending * self.n_inputs)
        self._e = np.zeros(3)
        self.saturated = 0
        self.active = False
        self.last_command = np.zeros(self.n_inputs)
        self.lost = ''

    def set_enabled(self, enabled: bool) -> None:
        """Enable or disable (disabled: zero currents, integrators cleared).

        Parameters
        ----------
        enabled : bool
        """
        self.enabled = bool(enabled)
        if not self.enabled:
            self._e[:] = 0.0
        else:
            self.lost = ''  # enabling is the operator's go-ahead after a loss

    def set_reference(self, position=None) -> None:
        """Set-point of the magnet's centre, world frame, m (None: the equilibrium).

        Parameters
        ----------
        position : array_like, shape (3,), or None
            m.

        Raises
        ------
        ValueError
            When the position is not three finite numbers.
        """
        if position is None:
            offset = np.zeros(3)
        else:
            p = np.asarray(position, dtype=float)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise ValueError(f'reference must be 3 finite numbers (m), got {position!r}')
            offset = p - self.x_eq[:3]
        self.reference = self.x_eq[:3] + offset
        self._dx_ss, self._u_ss = steady_state(self.linear.A, self.linear.B, offset)
        x_ss = self.x_eq.copy()
        x_ss[self.reduced] += self._dx_ss
        u = self._u_ss
        self._bias = u + self._Kx @ x_ss + self._Ki @ u + self._Kc @ np.tile(u, self._n_pending)

    def command(self, t: float, state=None, currents=None) -> np.ndarray:
        """Return the coil command for time ``t``.

        Parameters
        ----------
        t : float
            Time of the sample, s.
        state : array_like, shape (12,), optional
            The new estimate, or None when none arrived for this sample.
        currents : array_like, shape (n_s,), optional
            Measured coil currents of the sample, A (needed with coil dynamics;
            the last command is used when missing).

        Returns
        -------
        ndarray, shape (n_s,)
            Currents to command, A (zero when disabled or the input is stale).
        """
        if state is None:
            if not self.watchdog.check(t) or not self.enabled:
                return self._zero()
            return self.last_command.copy()  # one missing estimate: hold (ZOH)
        was_safe = self.watchdog.safe
        armed = self.watchdog.feed(t)
        if not armed or not self.enabled or self.lost:
            return self._zero()
        if was_safe:  # just re-armed: start clean
            self._e[:] = 0.0
        x = np.asarray(state, dtype=float)
        d0, d1, d2 = x[0] - self.x_eq[0], x[1] - self.x_eq[1], x[2] - self.x_eq[2]
        off = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if not off <= self.config.loss_distance:  # also NaN
            self.lost = (
                f'magnet lost: estimate {1e3 * off:.1f} mm from the equilibrium '
                f'(loss_distance {1e3 * self.config.loss_distance:.1f} mm) at t = {t:.4f} s'
            )
            self._e[:] = 0.0
            return self._zero()
        m = self.n_inputs
        # the coils follow the oldest pending command (no measurement: that command)
        i = self._c_prev[-m:] if currents is None or not self._has_i else currents
        clipped, saturated = lqr_law(
            x,
            np.asarray(i, dtype=float),
            self._c_prev,
            self._e,
            self._Kx,
            self._Ki,
            self._Kc,
            self._Ke,
            self._bias,
            self.limit,
        )
        if saturated:
            self.saturated += 1
        elif self._has_e:  # conditional integration (anti-windup)
            self._e += self.config.dt * (x[:3] - self.reference)
        self._c_prev[m:] = self._c_prev[:-m]  # the register shifts; the newest first
        self._c_prev[:m] = clipped
        self.last_command = clipped
        self.active = True
        return clipped.copy()

    def _zero(self) -> np.ndarray:
        self._c_prev = np.zeros(self._n_pending * self.n_inputs)
        self.last_command = np.zeros(self.n_inputs)
        self.active = False
        return np.zeros(self.n_inputs)

    def status(self) -> ControllerStatus:
        """Level and message for the diagnostics."""
        w = self.watchdog
        if self.lost:
            level, message = (
                'ERROR',
                (
                    f'{self.lost}; coils at zero current; put the magnet back, then enable '
                    '(or disable and enable) to levitate again'
                ),
            )
        elif w.safe:
            level, message = 'ERROR', f'input stale: {w.reason}; coils at zero current'
            if w.fresh:
                message += f'; re-arming ({w.fresh}/{w.rearm} fresh estimates)'
        elif not self.enabled:
            level, message = 'WARN', 'disabled: coils at zero current (enable to levitate)'
        elif not self.active:
            level, message = 'WARN', 'waiting for the first estimate'
        else:
            level, message = 'OK', 'levitating (LQR)'
        return ControllerStatus(level, message, self.active, w.timeouts, self.saturated)
