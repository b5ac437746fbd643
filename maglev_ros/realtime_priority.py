"""Real-time scheduling for a control loop's thread (Linux ``SCHED_FIFO``), opt-in.

A closed loop at 1 kHz on a time-shared machine is late whenever another
process holds the CPU it needs: on this 2-core machine, loaded to 5-6 by other
work, half of the periods of the loop on the virtual V4x board came late and
the magnet was lost. ``ros2_control``'s control node runs its loop thread
under ``SCHED_FIFO`` for the same reason; :func:`fifo_priority` does that for
the calling thread, for a block, and restores the thread's policy after.

It needs the right to do so (root, ``CAP_SYS_NICE`` or an ``rtprio`` limit in
``/etc/security/limits.conf``); without it the block runs at the normal
policy and the reason is returned, not raised. Linux keeps 5 % of each second
for other work (``sched_rt_runtime_us``), so a runaway thread cannot lock the
machine up.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ['fifo_priority']


@contextmanager
def fifo_priority(priority: int) -> Iterator[str]:
    """Run the calling thread under ``SCHED_FIFO`` at ``priority`` for the block.

    Parameters
    ----------
    priority : int
        1-99 (``ros2_control`` uses 50); 0: leave the scheduling alone.

    Yields
    ------
    str
        '' when the policy was set (or ``priority`` is 0), else why not (the
        block then runs at the normal policy).

    Raises
    ------
    ValueError
        If ``priority`` is outside 0-99.
    """
    if not 0 <= priority <= 99:
        raise ValueError(f'real-time priority must be 0 (none) to 99, got {priority!r}')
    if priority == 0:
        yield ''
        return
    if not hasattr(os, 'sched_setscheduler'):
        yield 'real-time scheduling is not available on this system'
        return
    previous = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as err:
        yield (
            f'SCHED_FIFO at priority {priority} refused ({err.strerror}): running at the '
            'normal policy; allow it with an rtprio limit (/etc/security/limits.conf) or '
            'CAP_SYS_NICE'
        )
        return
    try:
        yield ''
    finally:
        os.sched_setscheduler(0, previous[0], previous[1])
