"""Frozen-sensor detection: a run of identical 3-axis readings is treated as missing."""

from __future__ import annotations

import numpy as np

from .kernels import freeze_check

__all__ = ['FreezeDetector']


class FreezeDetector:
    """Per-sensor run length of identical readings.

    Under coil switching a Hall sensor may repeat one reading until it is
    reset (the firmware resets after 20 identical samples). A sensor is
    *frozen* once its reading (all three axes, bit for bit) has been the same
    ``run`` samples in a row; it stays frozen until the reading changes.
    Non-finite readings are missing too.

    With 0.1 mT noise and 0.098 mT steps, two consecutive readings of a still
    magnet agree on all three axes about 2 % of the time, so a run of 4 happens
    by chance about once in 10^5 samples per sensor (a few per minute at
    5 kHz): then one good reading is dropped, which costs nothing.

    Parameters
    ----------
    n_sensors : int
        Number of 3-axis sensors.
    run : int
        Identical readings in a row that make a sensor frozen (>= 2).
    """

    def __init__(self, n_sensors: int, run: int = 4):
        if run < 2:
            raise ValueError(f'run must be >= 2, got {run!r}')
        self.n_sensors = int(n_sensors)
        self.run = int(run)
        self.reset()

    def reset(self) -> None:
        """Forget the reading history and the counts (in place: compiled callers hold them)."""
        if not hasattr(self, 'runs'):
            self._last = np.empty((self.n_sensors, 3))
            self.runs = np.empty(self.n_sensors, dtype=np.int64)
            self.frozen = np.empty(self.n_sensors, dtype=bool)
            self.events = np.empty(self.n_sensors, dtype=np.int64)  # freezes seen
        self._last[:] = np.nan
        self.runs[:] = 0
        self.frozen[:] = False
        self.events[:] = 0

    def check(self, y: np.ndarray) -> np.ndarray:
        """Register one sample; return which sensors have a usable reading.

        Parameters
        ----------
        y : ndarray, shape (3 k,)
            Readings, T.

        Returns
        -------
        ndarray of bool, shape (k,)
            True where the sensor's reading is finite and not frozen.
        """
        available, frozen = freeze_check(y, self._last, self.runs, self.run)
        if frozen.any():
            self.events += frozen & ~self.frozen
        self.frozen[:] = frozen
        return available
