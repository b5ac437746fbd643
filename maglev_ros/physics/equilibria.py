"""Equilibria of the centred magnet, and the state resting at the first one."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .kernels import GRAVITY

__all__ = [
    'Equilibrium',
    'vertical_force',
    'find_equilibria',
    'rest_state',
]

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


def rest_state(model) -> np.ndarray:
    """Return the state of the centred, level magnet resting at its first equilibrium.

    The default initial state of the simulator, the default linearisation
    point and ``maglev-model simulate``'s start: one rule, written here.

    Parameters
    ----------
    model : MaggyModel
        The model.

    Returns
    -------
    ndarray, shape (12,)
        ``model.hover_state(z)`` at the lowest equilibrium height ``z`` (m).

    Raises
    ------
    ValueError
        If the model has no equilibrium (then give the state explicitly).
    """
    found = find_equilibria(model)
    if not found:
        raise ValueError(
            f'{model.params.name}: no equilibrium of the centred magnet; give the state'
        )
    return model.hover_state(found[0].z)
