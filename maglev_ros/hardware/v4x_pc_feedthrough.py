"""The coil field a V4x PC-control board leaves in its readings, measured before levitating.

The firmware removes each coil's direct field from the sensor's x and y axes
with slopes it measures at power-up (``shared/docs/teensy-protocol.md``): ten
readings at each of three PWM levels, with the sensor's noise, so each slope
is a few percent off (emulated: 0.4 mT/A measured as 0.36-0.44 mT/A). What is
left, up to 0.05 mT per ampere of a pair (emulated), is a direct path from the
commands to the readings that the loop's model does not have; with the
board's one sensor, whose x and y see the magnet's lateral motion weakly, it
loses the magnet in some boards (docs/boards.md).

:func:`measure_feedthrough` measures what each coil pair leaves, with the
magnet absent (as the board is at power-up): it drives each pair at a few
PWM levels and fits the processed field's change per ampere of the pair,
from the level means (the x and y readings are low-pass filtered, so their
noise is correlated from sample to sample). The loop's and the calibration's
board model then use it (``BoardProcessing.from_model(..., pairs=...)``).
:func:`wait_for_magnet` then waits until the magnet is in place.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    'FEEDTHROUGH_LEVELS',
    'MagnetPresentError',
    'PairFeedthrough',
    'measure_feedthrough',
    'measurement_time',
    'wait_for_magnet',
]

#: PWM differences each pair is driven at (0.7 and 1.4 A at 12 V, 4 ohm), zero first and last
FEEDTHROUGH_LEVELS = (0, 60, -60, 120, -120, 0)
#: T of processed |Bz| with the coils off above which the magnet counts as present (its
#: own field in place: several mT)
MAGNET_PRESENT = 1e-3
#: T a level's mean Bz may lie off the line through the coils' field (noise: about 0.01 mT)
MAGNET_MOVED = 5e-5


class MagnetPresentError(ValueError):
    """The board's field shows the magnet while it must be absent."""


@dataclass(frozen=True)
class PairFeedthrough:
    """The processed field per ampere of each coil pair, measured without the magnet.

    Attributes
    ----------
    response : ndarray, shape (3, 2)
        Bx, By, Bz per ampere of the x pair (column 0: x+ at +i, x- at -i)
        and of the y pair, T/A.
    std : ndarray, shape (3, 2)
        Standard deviations of ``response`` (from the scatter of the level
        means about the line), T/A.
    offset : ndarray, shape (3,)
        Processed field at zero current, T (the baseline's error: near zero).
    samples : int
        Readings used.
    """

    response: NDArray[np.float64]
    std: NDArray[np.float64]
    offset: NDArray[np.float64]
    samples: int

    def metadata(self) -> dict[str, str]:
        """Return the measurement as a bag's metadata: six numbers, T/A, for each key.

        ``board_feedthrough``: ``response``; ``board_feedthrough_std``: ``std``;
        row by row: Bx, By, Bz per ampere of the x pair and of the y pair.
        """

        def text(values: NDArray[np.float64]) -> str:
            return ' '.join(f'{float(v):.6e}' for v in np.asarray(values).ravel())

        return {'board_feedthrough': text(self.response), 'board_feedthrough_std': text(self.std)}

    @staticmethod
    def response_from(
        values: str | Sequence[float], name: str = 'board_feedthrough'
    ) -> NDArray[np.float64]:
        """Return the (3, 2) array of one of :meth:`metadata`'s texts (or six numbers), T/A.

        Parameters
        ----------
        values : str or sequence of float
            Six numbers, row by row, T/A (text: separated by spaces).
        name : str
            The key, for the error message.

        Raises
        ------
        ValueError
            If there are not six finite numbers.
        """
        items = values.split() if isinstance(values, str) else values
        try:
            out = np.asarray([float(v) for v in items], dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f'{name} must be six numbers, got {values!r}') from None
        if out.shape != (6,) or not np.all(np.isfinite(out)):
            raise ValueError(f'{name} must be six finite numbers, got {values!r}')
        return out.reshape(3, 2)

    def summary(self) -> str:
        """One line: the x and y readings' response to their own pair, mT/A, with std."""
        r, s = 1e3 * self.response, 1e3 * self.std
        return (
            f'x pair into Bx {r[0, 0]:+.4f} +- {s[0, 0]:.4f} mT/A, y pair into By '
            f'{r[1, 1]:+.4f} +- {s[1, 1]:.4f} mT/A (cross terms {r[1, 0]:+.4f}, '
            f'{r[0, 1]:+.4f}; Bz {r[2, 0]:+.4f}, {r[2, 1]:+.4f} mT/A; {self.samples} readings)'
        )


class _Pace:
    """Requests one period apart (the loop's rate), on ``clock``."""

    def __init__(self, period: float, clock=None, sleep=None) -> None:
        self.period = period
        self.clock = clock or time.monotonic
        self.sleep = sleep or time.sleep
        self.due = self.clock()

    def next(self) -> None:
        """Wait until one period after the last."""
        self.due += self.period
        wait = self.due - self.clock()
        if wait > 0:
            self.sleep(wait)


def measurement_time(
    period: float = 1e-3,
    levels: Sequence[int] = FEEDTHROUGH_LEVELS,
    settle: int = 20,
    hold: int = 100,
) -> float:
    """Return the s :func:`measure_feedthrough` takes with these settings (both pairs).

    Parameters
    ----------
    period, levels, settle, hold
        As :func:`measure_feedthrough`.
    """
    return 2 * len(levels) * (settle + hold) * period


def measure_feedthrough(
    link,
    *,
    levels: Sequence[int] = FEEDTHROUGH_LEVELS,
    settle: int = 20,
    hold: int = 100,
    period: float = 1e-3,
    clock: Callable[[], float] | None = None,
    sleep: Callable[[float], None] | None = None,
) -> PairFeedthrough:
    """Drive each coil pair at ``levels`` and fit its processed field per ampere.

    The magnet must be absent. The coils end at zero.

    Parameters
    ----------
    link : V4xPcLink
        The board's link (open).
    levels : sequence of int
        PWM differences each pair is held at, in turn.
    settle, hold : int
        Periods at each level before the readings count, and readings kept.
    period : float
        s between readings.
    clock, sleep : callable, optional
        Time source and wait (default the wall clock).

    Returns
    -------
    PairFeedthrough

    Raises
    ------
    MagnetPresentError
        The processed Bz shows the magnet with the coils off, or moves off the
        coils' line during the measurement (the coils are set to zero first).
    LinkError
        The board does not answer.
    """
    pace = _Pace(period, clock, sleep)
    response, std, offsets = np.zeros((3, 2)), np.zeros((3, 2)), []
    count = 0
    try:
        for pair in range(2):
            means_i, means_b = [], []
            for level in levels:
                command = (level, 0) if pair == 0 else (0, level)
                fields, currents = [], []
                for k in range(settle + hold):
                    pace.next()
                    cycle = link.command_and_sample(*command)
                    if k >= settle:  # the field is the board's sample before this command
                        fields.append(cycle.field_mT * 1e-3)
                        c = cycle.currents_A
                        currents.append((c[2 * pair] - c[2 * pair + 1]) / 2)
                fields = np.asarray(fields)
                bz = float(fields[:, 2].mean())
                if level == 0 and abs(bz) > MAGNET_PRESENT:  # the coils off: only a magnet
                    raise MagnetPresentError(
                        f'the board reads Bz {1e3 * bz:.1f} mT with the coils off: the magnet '
                        'is in place, but the coil feedthrough is measured without it; take '
                        'the magnet off the board and start again'
                    )
                means_i.append(np.mean(currents))
                means_b.append(fields.mean(axis=0))
                count += hold
            x = np.column_stack([np.ones(len(means_i)), means_i])
            coef, *_ = np.linalg.lstsq(x, np.asarray(means_b), rcond=None)
            dof = max(len(means_i) - 2, 1)
            scatter = np.asarray(means_b) - x @ coef
            cov = np.linalg.inv(x.T @ x)[1, 1]
            moved = float(np.max(np.abs(scatter[:, 2])))
            if moved > MAGNET_MOVED:
                raise MagnetPresentError(
                    f'the field moved during the measurement (Bz {1e3 * moved:.2f} mT off the '
                    "coils' line): the magnet came near; keep it away until the loop asks for it"
                )
            response[:, pair] = coef[1]
            std[:, pair] = np.sqrt(np.sum(scatter**2, axis=0) / dof * cov)
            offsets.append(coef[0])
    finally:
        link.command(0, 0)
    return PairFeedthrough(response, std, np.mean(offsets, axis=0), count)


def wait_for_magnet(
    link,
    field: float,
    *,
    share: float = 0.5,
    timeout: float = 60.0,
    period: float = 1e-3,
    clock: Callable[[], float] | None = None,
    sleep: Callable[[float], None] | None = None,
) -> float:
    """Wait until the processed Bz reaches ``share`` of the magnet's field in place.

    A hand brings the magnet over the board: its field grows as it comes
    closer; from half of its field at the equilibrium on, the loop can take
    it (a magnet a few ten percent weaker or stronger than believed passes
    too).

    Parameters
    ----------
    link : V4xPcLink
        The board's link (open; the coils at zero).
    field : float
        Processed Bz with the magnet at its equilibrium, T (the model's).
    share : float
        Share of ``field`` the reading must reach (same sign).
    timeout : float
        s to wait at most.
    period, clock, sleep
        As :func:`measure_feedthrough`.

    Returns
    -------
    float
        The s waited.

    Raises
    ------
    TimeoutError
        No magnet within ``timeout``.
    """
    pace = _Pace(period, clock, sleep)
    start = pace.due
    while True:
        bz = link.command_and_sample(0, 0).field_mT[2] * 1e-3
        if bz * np.sign(field) >= share * abs(field):
            return pace.clock() - start
        if pace.clock() - start > timeout:
            raise TimeoutError(
                f'no magnet in place within {timeout:g} s (the board reads Bz '
                f'{1e3 * bz:.2f} mT, the magnet at its height gives {1e3 * field:.1f} mT): '
                'hold the magnet over the centre of the board'
            )
        pace.next()
