"""Scheduling of the DDS threads in a node process (Linux).

A Fast DDS reliable writer with a matched reader restarts its heartbeat
timer on every sample it writes, and each restart wakes the participant's
event thread (``dds.ev.<n>``). At 5 kHz with two topics that is about
10 000 wake-ups per second; Linux lets the woken thread preempt the
publishing thread, so every message costs two context switches. Measured
with the driver at 5 kHz and a subscriber process (``benchmarks/driver.py``):
12 700 event-thread wake-ups and 13 500 involuntary switches of the driver's
I/O thread per second, about a third of the driver's CPU time.

:func:`relax_event_threads` moves the event threads to ``SCHED_BATCH``: they
still get their fair share of the CPU, but their wake-ups no longer preempt
a running thread; they run when the publisher blocks (at the latest after
one scheduler time slice, a few ms). The event thread only runs timers -
heartbeats (every 3 s by default), acknowledgement responses (5 ms delay by
default), liveliness - for which that delay is harmless; the threads that
receive data (shared-memory and UDP listeners) are left alone, so commands
arrive as fast as before. Other DDS implementations name their threads
differently and are left untouched.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ['EVENT_THREAD_PREFIX', 'relax_event_threads']

EVENT_THREAD_PREFIX = 'dds.ev.'  # Fast DDS names its event threads dds.ev.<participant>


def relax_event_threads(prefix: str = EVENT_THREAD_PREFIX) -> list[int]:
    """Put this process's DDS event threads into ``SCHED_BATCH``.

    Parameters
    ----------
    prefix : str, optional
        Thread name prefix (``/proc/self/task/<tid>/comm``) of the event threads.

    Returns
    -------
    list of int
        Thread ids changed now or already in ``SCHED_BATCH``; empty where the
        platform has no ``/proc`` or no ``SCHED_BATCH`` (nothing is changed),
        or no thread matches.
    """
    batch = getattr(os, 'SCHED_BATCH', None)
    tasks = Path('/proc/self/task')
    if batch is None or not tasks.is_dir():
        return []
    changed = []
    for task in tasks.iterdir():
        try:
            name = (task / 'comm').read_text().strip()
            if not name.startswith(prefix):
                continue
            tid = int(task.name)
            if os.sched_getscheduler(tid) != batch:
                os.sched_setscheduler(tid, batch, os.sched_param(0))
        except (OSError, ValueError):  # the thread ended, or the change is not allowed
            continue
        changed.append(tid)
    return sorted(changed)
