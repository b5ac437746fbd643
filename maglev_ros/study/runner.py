"""One study run: its closed loop, judged by the success criterion, as a table row.

:func:`run_task` is what the workers execute; it is a plain function of a
:class:`~maglev_ros.study.sampling.RunTask`, so the same task gives the same
row on any machine with the package installed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .loop_adapter import simulate
from .sampling import RunTask
from .spec import SuccessCriterion

__all__ = ['METRICS', 'OUTCOMES', 'judge', 'run_task']

#: Outcomes, best first.
OUTCOMES = ('ok', 'not_settled', 'left_bounds', 'controller_off', 'crashed', 'error')
#: Result columns after the parameters: name -> (unit, meaning).
METRICS = {
    'success': ('', 'the run met the success criterion'),
    'outcome': ('', ' / '.join(OUTCOMES)),
    'max_excursion': ('m', 'largest |x|, |y|, |z - z_eq| over the run'),
    'rms_x': ('m', 'RMS of x over the last window'),
    'rms_y': ('m', 'RMS of y over the last window'),
    'rms_z': ('m', 'RMS of z - z_eq over the last window'),
    'crash_time': ('s', 'when the magnet crashed or left the workspace (NaN: never)'),
    'peak_current': ('A', 'largest |coil current|'),
    'reason': ('', "the simulator's crash message"),
}


def judge(result, duration: float, success: SuccessCriterion) -> dict[str, Any]:
    """Return the metric columns of a run.

    Parameters
    ----------
    result : LoopResult
        The run.
    duration : float
        s it was asked to last.
    success : SuccessCriterion
    """
    err = result.position_error()
    excursion = float(np.max(np.abs(err))) if err.size else float('nan')
    tail = err[result.t >= duration - success.window]
    if result.crashed or not tail.size:
        rms = np.full(3, np.nan)
    else:
        rms = np.sqrt(np.mean(tail**2, axis=0))
    off = not result.crashed and result.level.size and result.level[-1] != 'OK'
    if result.crashed:
        outcome = 'crashed'
    elif off:
        # the controller gave up (magnet lost, input stale, no magnet): coils at zero;
        # a magnet left exactly at the plant's equilibrium would otherwise pass
        outcome = 'controller_off'
    elif excursion > success.bound:
        outcome = 'left_bounds'
    elif not np.all(rms <= success.rms):
        outcome = 'not_settled'
    else:
        outcome = 'ok'
    crash_time = float(result.t[-1] + result.dt) if result.crashed else float('nan')
    currents = result.currents
    return {
        'success': outcome == 'ok',
        'outcome': outcome,
        'max_excursion': excursion,
        'rms_x': float(rms[0]),
        'rms_y': float(rms[1]),
        'rms_z': float(rms[2]),
        'crash_time': crash_time,
        'peak_current': float(np.max(np.abs(currents))) if currents.size else 0.0,
        'reason': result.reason if not off else _last_controller_message(result),
    }


def _last_controller_message(result) -> str:
    said = [m for m in result.messages if m.startswith('controller')]
    return said[-1] if said else f'controller {result.level[-1]} at the end'


def run_task(task: RunTask) -> dict[str, Any]:
    """Run one study run and return its row: run, seed, parameters, metrics.

    Parameters
    ----------
    task : RunTask
    """
    values = task.as_dict()
    try:
        result = simulate(values, task.seed, task.duration)
    except ValueError as exc:  # the loop cannot be built (e.g. an LQR design fails)
        metrics = {name: float('nan') for name in METRICS}
        metrics.update(success=False, outcome='error', peak_current=float('nan'))
        metrics['reason'] = str(exc).strip().splitlines()[0] if str(exc).strip() else 'error'
    else:
        metrics = judge(result, task.duration, task.success)
    return {'run': task.index, 'seed': task.seed, **values, **metrics}
