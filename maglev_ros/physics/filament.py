"""Filament layout of a solenoid: the published grid of current loops."""

from __future__ import annotations

import math

import numpy as np

__all__ = ['filament_loops']


def filament_loops(radius: float, length: float, turns: float) -> tuple[np.ndarray, np.ndarray]:
    """Heights and radii of the filament loops of one solenoid.

    The ``turns`` are spread over the coil's length and radius:
    ``n_axial = floor(l sqrt(n_w / (l r)))``, ``n_radial = round(n_w / n_axial)``;
    loops sit at ``n_axial`` heights evenly spaced from -l/2 to +l/2 (ends
    included) and at radii ``k r / n_radial`` for ``k = 1 .. n_radial - 1``.
    Each loop carries the coil current. This is the published layout (456 loops
    for V2, not exactly n_w); its dipole moment is smaller than a full-radius
    solenoid's because the loops fill the cross-section.

    Parameters
    ----------
    radius : float
        Coil radius r, m.
    length : float
        Coil length l, m.
    turns : float
        Number of turns n_w.

    Returns
    -------
    heights : ndarray, shape (n_axial,)
        Loop heights relative to the coil centre, m.
    radii : ndarray, shape (n_radial - 1,)
        Loop radii, m.
    """
    if radius <= 0 or length <= 0 or turns <= 0:
        raise ValueError(
            f'radius, length and turns must be positive, got {radius!r}, {length!r}, {turns!r}'
        )
    n_axial = max(1, math.floor(length * math.sqrt(turns / (length * radius))))
    n_radial = max(2, round(turns / n_axial))
    heights = np.linspace(-length / 2, length / 2, n_axial)
    radii = radius * np.arange(1, n_radial) / n_radial
    return heights, radii
