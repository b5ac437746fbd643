"""Closed-loop records of the simulated magnet with a PRBS on the coils (cached per process).

The ROS-free closed loop (:func:`maglev_ros.control.closed_loop.make_closed_loop`:
simulator -> KF -> LQR, maggy_v2, sensor noise and quantisation, coil
dynamics) with a PRBS added to the controller's command, after 0.4 s of
settling.  ``pattern`` says which coils get it: ``z`` all four (+r), ``x`` the
x pair (+r, -r), ``all`` an independent PRBS per coil.
"""

from functools import lru_cache

import numpy as np

from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.excitation.signals import prbs

SETTLE = 2000  # samples (0.4 s at 5 kHz)
PATTERNS = {'z': (1.0, 1.0, 1.0, 1.0), 'x': (1.0, -1.0, 0.0, 0.0)}


@lru_cache(maxsize=16)
def record(pattern, amplitude, clock, samples, seed):
    """Return ``(result, r)``: the loop's result after settling and the PRBS (samples, 4)."""
    loop = make_closed_loop('maggy_v2', seed=seed)
    if pattern == 'all':
        r = np.column_stack(
            [prbs(samples, amplitude, (0.0, clock), seed=10 * seed + k) for k in range(4)]
        )
    else:
        r = np.outer(prbs(samples, amplitude, (0.0, clock), seed=seed), PATTERNS[pattern])
    excitation = np.vstack([np.zeros((SETTLE, 4)), r])
    result = loop.run((SETTLE + samples) * loop.simulator.dt, excitation=excitation)
    assert not result.crashed, result.reason
    keep = slice(SETTLE, None)
    fields = {name: getattr(result, name) for name in result.__dataclass_fields__}
    for name in ('t', 'x', 'estimate', 'std', 'nis', 'dof', 'command', 'currents',
                 'reference', 'level', 'frozen', 'readings'):  # fmt: skip
        fields[name] = fields[name][keep]
    return type(result)(**fields), r


def lab_x(seed=0, samples=25000):
    """The lab's x channel: ``Bx_0`` against ``u_x`` (total command), +-0.1 A PRBS on the x pair.

    Means removed (the lab's detrend); ``u_x = (u_x+ - u_x-) / 2`` includes the excitation.
    """
    from maglev_ros.sysid import IdData

    result, r = record('x', 0.1, 0.2, samples, seed)
    u = result.command + r
    ux = 0.5 * (u[:, 0] - u[:, 1])
    bx = result.readings[:, 0]
    return IdData(bx - bx.mean(), ux - ux.mean(), result.dt, ['Bx_0'], ['u_x'], ['T'], ['A'])
