"""What the simulator reports about its session: diagnostics and log lines, ROS-free."""

from __future__ import annotations

from ..health import ERROR, OK, Health
from ..topics import SIMULATOR_RESET_SERVICE
from .session import SimulationSession, timeout_line

__all__ = ['crash_line', 'session_health', 'timeout_line']  # timeout_line: the session's


def session_health(session: SimulationSession, magnet: str) -> Health:
    """Run state and counters of a session, for ``/diagnostics``.

    Parameters
    ----------
    session : SimulationSession
        The session (its simulator gives time and crash details).
    magnet : str
        The magnet mode (``free``, ``fixed``, ``absent``), reported as is.

    Returns
    -------
    Health
        ERROR after a crash (until a reset), else OK: paused, waiting for the
        command publisher (lockstep before its start), or running.
    """
    sim = session.sim
    if sim.crashed:
        level = ERROR
        message = f'crashed at t = {sim.crash_time:.4f} s: {sim.reason}; reset to recover'
    elif session.paused:
        level, message = OK, 'paused'
    elif not session.started:
        level, message = OK, 'waiting for the command publisher'
    else:
        level, message = OK, f'running ({session.mode})'
    values = {
        'mode': session.mode,
        'magnet': magnet,
        'parameter set': sim.model.params.name,
        'simulated time (s)': f'{sim.time:.6f}',
        'real-time factor': f'{session.real_time_factor:.3f}',
        'command lag (samples)': '' if session.command_lag is None else session.command_lag,
        'crash reason': sim.reason,
        'crash time (s)': '' if sim.crash_time is None else f'{sim.crash_time:.6f}',
        'crash state': (
            '' if sim.crash_state is None else ' '.join(f'{v:.6g}' for v in sim.crash_state)
        ),
    }
    values.update({name.replace('_', ' '): v for name, v in session.counters.items()})
    return Health(level, message, values)


def crash_line(session: SimulationSession) -> str:
    """Describe a crash in one log line: time, reason, pose, what to do.

    Parameters
    ----------
    session : SimulationSession
        A session whose simulator crashed.

    Returns
    -------
    str
        One line.
    """
    sim = session.sim
    state = ' '.join(f'{v:.4g}' for v in sim.crash_state[:6])
    return (
        f'magnet crashed at t = {sim.crash_time:.4f} s ({sim.reason}); pose {state}; '
        f'integration stopped: call {SIMULATOR_RESET_SERVICE}'
    )
