"""Keep Python's garbage collector from stalling a real-time loop.

CPython's cyclic collector runs when enough container objects were
allocated; a collection of the oldest generation traverses every tracked
object of the process. After a loop has been built (the physics model, the
estimator, the controller, numba's dispatchers, numpy and, in a ROS process,
rclpy: some 200 000 objects), one such collection takes 45-85 ms on this
2-core machine, and 200-270 ms when the process is descheduled meanwhile:
measured inside the real-time loop on a V4x PC-control board, where it came
after 0.6-0.7 s and the magnet (an unstable plant, time constant about 20 ms)
was lost during it. The virtual board's process had its own (50 ms).

:func:`frozen_heap` collects once, then moves every object alive into the
collector's permanent generation (:func:`gc.freeze`): later collections
traverse only what the loop allocates (a few thousand objects), and the
collector stays on, so cycles made meanwhile are still freed. On exit the
heap is unfrozen (a later collection sees everything again).
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ['frozen_heap']


@contextmanager
def frozen_heap() -> Iterator[int]:
    """Freeze the objects alive now out of the collector's reach for the block.

    Yields
    ------
    int
        Objects frozen (:func:`gc.get_freeze_count`).

    Notes
    -----
    Nested use is harmless: the inner block freezes what was allocated since
    and leaves the heap frozen on exit; the outermost block unfreezes it.
    """
    outermost = gc.get_freeze_count() == 0
    gc.collect()
    gc.freeze()
    try:
        yield gc.get_freeze_count()
    finally:
        if outermost:
            gc.unfreeze()
