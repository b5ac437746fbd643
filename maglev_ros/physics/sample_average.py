"""Average a simulation's samples in groups: a sensor read faster than it is sent.

A board's firmware may sample its sensor faster than it reports and send the
mean of each group (the V4x firmware low-pass filters its samples; a host at
1 kHz can take the mean of five 5 kHz samples). :class:`SampleAverager` does
that to the simulator's samples: each group of ``n`` consecutive samples
becomes one sample whose reading is the group's mean (the noise's standard
deviation divided by sqrt(n)), and whose stamp, index, state and currents are
the group's last (the instant the mean is known). It is what lets separate
processes exchange samples at a rate the middleware sustains without
throwing away the information of the faster sensor.
"""

from __future__ import annotations

import numpy as np

from .session import SampleBatch

__all__ = ['SampleAverager']


class SampleAverager:
    """Means of ``n`` consecutive samples, across batches (module docstring).

    Parameters
    ----------
    n : int
        Samples per mean (1: samples pass unchanged).

    Raises
    ------
    ValueError
        If ``n`` is not a positive integer.
    """

    def __init__(self, n: int) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f'samples per mean must be an integer >= 1, got {n!r}')
        self.n = int(n)
        self._held: SampleBatch | None = None  # the samples of an unfinished group

    def reset(self) -> None:
        """Drop an unfinished group (a new run starts)."""
        self._held = None

    def add(self, batch: SampleBatch) -> SampleBatch:
        """Return the means of the groups ``batch`` completes, in order.

        Parameters
        ----------
        batch : SampleBatch
            The next samples of the run (shape (m, ...)).

        Returns
        -------
        SampleBatch
            One sample per completed group (``crashed`` as ``batch``'s); the
            samples of an unfinished group wait for the next call.
        """
        n = self.n
        if n == 1:
            return batch
        held = self._held
        if held is not None and len(held):
            batch = SampleBatch(
                *(np.concatenate([getattr(held, f), getattr(batch, f)]) for f in _FIELDS),
                crashed=batch.crashed,
            )
        whole = (len(batch) // n) * n
        rest = slice(whole, len(batch))
        self._held = SampleBatch(*(getattr(batch, f)[rest] for f in _FIELDS))
        last = slice(n - 1, whole, n)
        k = whole // n
        width = batch.readings.shape[1]
        readings = batch.readings[:whole].reshape(k, n, width).mean(axis=1)
        return SampleBatch(
            batch.indices[last] // n,
            batch.stamps_ns[last],
            readings,
            batch.states[last],
            batch.currents[last],
            crashed=batch.crashed,
        )


_FIELDS = ('indices', 'stamps_ns', 'readings', 'states', 'currents')
