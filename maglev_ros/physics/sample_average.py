"""Average a simulation's samples in groups: a sensor read faster than it is sent.

A board's firmware may sample its sensor faster than it reports and send the
mean of each group (the V4x firmware low-pass filters its samples; a host at
1 kHz can take the mean of five 5 kHz samples). :class:`SampleAverager` does
that to the simulator's samples: the samples ``(m - 1) n + 1 .. m n`` of a run
become its sample ``m``, whose reading and coil currents are the group's means
(the noise's standard deviation divided by sqrt(n)), and whose stamp and state
are the group's last, sample ``m n`` (the instant the mean is known). The
run's initial sample 0 passes alone as sample 0: the averaged samples then
lie on the grid of the slower rate from the run's start, and a simulator
stepping a burst of ``n`` samples per wake-up ends a group with each burst
(a command received between bursts applies from a group's start).

It is what lets separate processes exchange samples at a rate the middleware
sustains without throwing away the information of the faster sensor. The
estimator models such a sample as what it is, a mean over the group
(:mod:`maglev_ros.estimation.group_mean`): with the sensor's one reading of
delay, the readings are of the states from the previous sample's instant on,
and the estimate is predicted to the stamp.
"""

from __future__ import annotations

import numpy as np

from .sample_batch import SampleBatch

__all__ = ['SampleAverager']


class SampleAverager:
    """Means of groups of ``n`` samples by their run index, across batches (module docstring).

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
            samples of an unfinished group wait for the next call. Samples
            must come in order of their run index, as a session returns them.
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
        ends = np.flatnonzero(batch.indices % n == 0)  # each group's last sample
        whole = int(ends[-1]) + 1 if len(ends) else 0
        rest = slice(whole, len(batch))
        self._held = SampleBatch(*(getattr(batch, f)[rest] for f in _FIELDS))
        if not whole:
            return SampleBatch(*(getattr(batch, f)[:0] for f in _FIELDS), crashed=batch.crashed)
        starts = np.concatenate([[0], ends[:-1] + 1]).astype(np.intp)
        counts = (ends + 1 - starts)[:, None]
        return SampleBatch(
            batch.indices[ends] // n,
            batch.stamps_ns[ends],
            np.add.reduceat(batch.readings[:whole], starts, axis=0) / counts,
            batch.states[ends],
            np.add.reduceat(batch.currents[:whole], starts, axis=0) / counts,
            crashed=batch.crashed,
        )


_FIELDS = ('indices', 'stamps_ns', 'readings', 'states', 'currents')
