"""Equilibria of the centred magnet and the fast model's solenoid radius correction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .kernels import GRAVITY
from .parameters import MaggyParameters

__all__ = [
    'Equilibrium',
    'vertical_force',
    'find_equilibria',
    'solenoid_radius_correction',
    'CORRECTION_TEST_CURRENT',
]

#: Current in every solenoid when matching the fast model to the filament model, A.
CORRECTION_TEST_CURRENT = 100.0
_STIFFNESS_STEP = 1e-6  # m, central difference for dF_z/dz


@dataclass(frozen=True)
class Equilibrium:
    """A vertical equilibrium of the centred, level magnet with u = 0.

    Attributes
    ----------
    z : float
        Height of the magnet's centre, m.
    stiffness : float
        dF_z/dz at the equilibrium, N/m (negative: vertically stable).
    inverted : bool
        True for the flipped magnet (J -> -J).
    """

    z: float
    stiffness: float
    inverted: bool = False

    @property
    def vertically_stable(self) -> bool:
        """True when dF_z/dz < 0."""
        return self.stiffness < 0


def vertical_force(model, z, u=None) -> np.ndarray:
    """Net vertical force F_z - m g on the centred, level magnet, N.

    Parameters
    ----------
    model : MaggyModel
        The model.
    z : float or array_like, shape (k,)
        Heights of the magnet's centre, m.
    u : array_like, shape (n_s,), optional
        Solenoid currents, A.

    Returns
    -------
    ndarray, shape like ``z``
    """
    heights = np.atleast_1d(np.asarray(z, dtype=float))
    weight = model.params.magnet.mass * GRAVITY
    out = np.array([model.wrench(model.hover_state(h), u)[2] - weight for h in heights])
    return out.reshape(np.shape(z))


def find_equilibria(
    model, z_max: float | None = None, grid_points: int | None = None, inverted: bool = False
) -> list[Equilibrium]:
    """All heights where the centred magnet floats with u = 0.

    The net vertical force is bracketed on a grid from just above the base
    (top of the tallest component plus half the magnet's thickness) to
    ``z_max``; every sign change is refined with Brent's method.

    Parameters
    ----------
    model : MaggyModel
        The model (use ``model.inverted()`` or ``inverted=True`` for J -> -J).
    z_max : float, optional
        Upper end of the search, m (default: the workspace's top).
    grid_points : int, optional
        Bracketing grid size (default 600 for fast, 150 otherwise).
    inverted : bool
        Search the flipped magnet.

    Returns
    -------
    list of Equilibrium
        In increasing height.
    """
    if inverted:
        model = model.inverted()
    params = model.params
    z_min = params.base_top + params.magnet.thickness / 2 + 1e-6
    z_top = float(params.workspace.upper[2]) if z_max is None else float(z_max)
    if z_top <= z_min:
        raise ValueError(f'z_max must exceed the lowest height {z_min:.6f} m, got {z_top}')
    n = grid_points or (600 if model.options.field == 'fast' else 150)
    grid = np.linspace(z_min, z_top, n)
    values = vertical_force(model, grid)
    found = []
    for k in np.nonzero(np.sign(values[:-1]) * np.sign(values[1:]) <= 0)[0]:
        if values[k] == 0.0:
            z_eq = grid[k]
        elif values[k + 1] == 0.0:
            continue  # counted at the next bracket
        else:
            z_eq = brentq(
                lambda h: float(vertical_force(model, h)),
                grid[k],
                grid[k + 1],
                xtol=1e-15,
                rtol=4 * np.finfo(float).eps,
                maxiter=200,
            )
        step = _STIFFNESS_STEP
        stiffness = float(
            (vertical_force(model, z_eq + step) - vertical_force(model, z_eq - step)) / (2 * step)
        )
        found.append(Equilibrium(float(z_eq), stiffness, inverted))
    return found


def solenoid_radius_correction(params: MaggyParameters) -> float:
    """Solenoid radius factor c that makes the fast model match the filament model.

    At the first (lowest) equilibrium of the uncorrected fast model (which does
    not depend on c: the solenoids carry no current there), with 100 A in every
    solenoid, c is chosen so that the fast model's total vertical force equals
    the filament model's (magnet as a current sheet over its rim surface).
    This is the published procedure; it is deterministic.

    Parameters
    ----------
    params : MaggyParameters
        The parameter set (its override, if any, is ignored here).

    Returns
    -------
    float
        The factor c (about 0.56 for the published sets).

    Raises
    ------
    ValueError
        No equilibrium, or no factor in (0.01, 3] matches.
    """
    from .model import MaggyModel, ModelOptions

    fast = MaggyModel(params, ModelOptions(field='fast', correction='none'))
    found = find_equilibria(fast)
    if not found:
        raise ValueError(f'{params.name}: no equilibrium, cannot compute the solenoid correction')
    z_eq = found[0].z
    u = np.full(params.solenoids.count, CORRECTION_TEST_CURRENT)
    filament = MaggyModel(params, ModelOptions(field='filament'))
    target = float(vertical_force(filament, z_eq, u))

    def mismatch(c: float) -> float:
        model = MaggyModel(params, ModelOptions(field='fast', correction=c))
        return float(vertical_force(model, z_eq, u)) - target

    grid = np.linspace(0.05, 3.0, 60)
    values = [mismatch(c) for c in grid]
    for k in range(len(grid) - 1):
        if np.sign(values[k]) != np.sign(values[k + 1]):
            return float(brentq(mismatch, grid[k], grid[k + 1], xtol=1e-14, rtol=1e-14))
    raise ValueError(
        f'{params.name}: no solenoid radius factor in (0.05, 3] matches the filament model'
    )
