"""The Maggy model: a parameter set bound to modelling options.

:class:`MaggyModel` gives the base field, the force and torque on the
levitating magnet, the 12-state dynamics ``f(x, u)`` and the sensor model
``h(x, u)`` for the three field models of ``maggy-model.md``:

``fast`` (default)
    every cylinder is one current loop at its centre; the magnet is a rim of
    ``rim_points`` current elements. Compiled with numba.
``accurate``
    every cylinder is a uniform current sheet (exact field of a uniformly
    magnetised cylinder); the magnet is a current sheet sampled over its rim
    surface (``rim_points`` x ``axial_points``).
``filament``
    as ``accurate``, but each solenoid is the published grid of filament
    loops. Slow: the reference used to calibrate the fast model.

State ``x`` (12): x, y, z (m), alpha, beta, gamma (rad, R = Rz Ry Rx), vx, vy, vz
(m/s, world frame), wx, wy, wz (rad/s, body frame). Input ``u``: solenoid
currents (A), order x+, x-, y+, y-.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from . import kernels
from .equilibria import find_equilibria, vertical_force
from .filament import filament_loops
from .loop import MU0, as_points, loop_field
from .parameters import MaggyParameters, load_parameters
from .sheet import sheet_field

__all__ = [
    'FIELD_MODELS',
    'TORQUE_MODES',
    'KINEMATICS',
    'STATE_NAMES',
    'DEFAULT_RIM_POINTS',
    'DEFAULT_AXIAL_POINTS',
    'CORRECTION_TEST_CURRENT',
    'ModelOptions',
    'MaggyModel',
    'make_model',
    'rim_angles',
    'solenoid_radius_correction',
]

FIELD_MODELS = ('fast', 'accurate', 'filament')
TORQUE_MODES = ('true', 'published')
KINEMATICS = ('rigid', 'published')
STATE_NAMES = ('x', 'y', 'z', 'alpha', 'beta', 'gamma', 'vx', 'vy', 'vz', 'wx', 'wy', 'wz')

#: Rim points of the fast model. The periodic trapezoidal rule converges
#: geometrically: 32 points agree with 400 to about 1e-15 (V2) and 3e-11 (V4)
#: relative in force at the equilibria and to better than 1e-9 within 3 mm /
#: 0.1 rad of them (tests and benchmarks/physics.py).
DEFAULT_RIM_POINTS = 32
#: Points across the thickness of the accurate/filament rim surface (odd), and
#: around it: the published reference's 21 x 100 grid.
DEFAULT_AXIAL_POINTS = 21
DEFAULT_SURFACE_RIM_POINTS = 100


@dataclass(frozen=True)
class ModelOptions:
    """Modelling choices.

    Attributes
    ----------
    field : {'fast', 'accurate', 'filament'}
        Field model.
    torque : {'true', 'published'}
        ``true``: moment of the rim forces (default). ``published``: the
        reference code's ``R l integral K0 n_z x B`` (a force, tens of times too
        large; for reproducing the lab's MATLAB linearisations).
    kinematics : {'rigid', 'published'}
        ``rigid``: ZYX Euler-angle kinematics with body rates and body-frame
        torque (default). ``published``: Euler rates = w, world torque.
    rim_points : int or None
        Points on the rim (None: 32 for fast, 100 for accurate/filament).
    axial_points : int
        Points across the thickness for accurate/filament (odd).
    correction : float, 'auto' or 'none'
        Solenoid radius factor of the fast model: ``auto`` uses the parameter
        file's override if any, else computes it from the filament model.
    """

    field: str = 'fast'
    torque: str = 'true'
    kinematics: str = 'rigid'
    rim_points: int | None = None
    axial_points: int = DEFAULT_AXIAL_POINTS
    correction: float | str = 'auto'

    def __post_init__(self):
        for name, allowed in (
            ('field', FIELD_MODELS),
            ('torque', TORQUE_MODES),
            ('kinematics', KINEMATICS),
        ):
            value = getattr(self, name)
            if value not in allowed:
                raise ValueError(f'{name} must be one of {", ".join(allowed)}, got {value!r}')
        if self.rim_points is not None and (
            not isinstance(self.rim_points, int) or self.rim_points < 3
        ):
            raise ValueError(f'rim_points must be an integer >= 3, got {self.rim_points!r}')
        if (
            not isinstance(self.axial_points, int)
            or self.axial_points < 1
            or (self.axial_points % 2 == 0)
        ):
            raise ValueError(
                f'axial_points must be an odd integer >= 1, got {self.axial_points!r}'
            )
        if isinstance(self.correction, str):
            if self.correction not in ('auto', 'none'):
                raise ValueError(
                    f"correction must be 'auto', 'none' or a positive number, "
                    f'got {self.correction!r}'
                )
        elif not (isinstance(self.correction, (int, float)) and self.correction > 0):
            raise ValueError(f'correction must be positive, got {self.correction!r}')


_CORRECTION_CACHE: dict[str, float] = {}


def _params_key(params: MaggyParameters) -> str:
    digest = hashlib.sha1()
    for cyl in (params.solenoids, params.permanent_magnets):
        for arr in dataclasses.astuple(cyl):
            digest.update(np.ascontiguousarray(arr).tobytes())
    m = params.magnet
    digest.update(np.array([m.radius, m.thickness, m.polarization, m.mass]).tobytes())
    return digest.hexdigest()


def rim_angles(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Cosines and sines of ``n`` evenly spaced rim angles 2 pi i / n.

    For n divisible by 4 the tables are built from the first quadrant by
    reflection, so they are exactly mirror-symmetric (cos(pi - t) = -cos t,
    sin(-t) = -sin t, exact zeros on the axes) and a centred magnet in a
    symmetric base feels exactly zero horizontal force.

    Parameters
    ----------
    n : int
        Number of rim points.

    Returns
    -------
    cos, sin : ndarray, shape (n,)
    """
    theta = 2.0 * np.pi * np.arange(n) / n
    cos, sin = np.cos(theta), np.sin(theta)
    if n % 4 == 0:
        q = n // 4
        c1 = cos[: q + 1].copy()
        s1 = sin[: q + 1].copy()
        c1[q], s1[q] = 0.0, 1.0
        s1[0] = 0.0
        for i in range(q + 1):
            for j, (c, s) in enumerate(
                ((c1[i], s1[i]), (-c1[i], s1[i]), (-c1[i], -s1[i]), (c1[i], -s1[i]))
            ):
                index = (i, 2 * q - i, 2 * q + i, n - i)[j] % n
                cos[index], sin[index] = c, s
    return cos, sin


class MaggyModel:
    """A parameter set with modelling options: field, force, f(x, u), h(x, u).

    Parameters
    ----------
    params : MaggyParameters
        The physical parameter set.
    options : ModelOptions, optional
        Modelling choices (defaults: fast field, true torque, rigid kinematics).
    """

    def __init__(self, params: MaggyParameters, options: ModelOptions | None = None):
        self.params = params
        self.options = options or ModelOptions()
        opts = self.options
        self.n_inputs = params.solenoids.count
        self.n_outputs = 3 * len(params.sensors)
        magnet = params.magnet
        self.k0 = -magnet.polarization / MU0  # rim surface current density, A/m
        default_n = DEFAULT_RIM_POINTS if opts.field == 'fast' else DEFAULT_SURFACE_RIM_POINTS
        self.rim_points = opts.rim_points or default_n
        self._cos, self._sin = rim_angles(self.rim_points)
        self._torque_mode = (
            kernels.TORQUE_TRUE if opts.torque == 'true' else kernels.TORQUE_PUBLISHED
        )
        self._kinematics = (
            kernels.KINEMATICS_RIGID
            if opts.kinematics == 'rigid'
            else kernels.KINEMATICS_PUBLISHED
        )
        self._inertia = np.array(magnet.inertia, dtype=float)
        s = params.sensors
        self._sensor_pos = np.array([x.position for x in s], dtype=float).reshape(-1, 3)
        self._sensor_rot = np.array([x.rotation for x in s], dtype=float).reshape(-1, 3, 3)
        self._sensor_gain = np.array([x.gain for x in s], dtype=float).reshape(-1, 3)
        self._sensor_offset = np.array([x.offset for x in s], dtype=float).reshape(-1, 3)
        self._correction: float | None = None
        self._loops = None  # packed loop sources, built on first use
        self._work = None  # kernel scratch space, built on first use
        self._fast_args = None
        self._measurement_args = None

    # ------------------------------------------------------------------ sources
    @property
    def correction(self) -> float:
        """Solenoid radius factor used by this model (1 for accurate/filament)."""
        if self.options.field != 'fast':
            return 1.0
        if self._correction is None:
            self._correction = self._resolve_correction()
        return self._correction

    def _resolve_correction(self) -> float:
        choice = self.options.correction
        if choice == 'none' or self.params.solenoids.count == 0:
            return 1.0
        if not isinstance(choice, str):
            return float(choice)
        if self.params.solenoid_radius_correction is not None:
            return float(self.params.solenoid_radius_correction)
        key = _params_key(self.params)
        if key not in _CORRECTION_CACHE:
            _CORRECTION_CACHE[key] = solenoid_radius_correction(self.params)
        return _CORRECTION_CACHE[key]

    def _loop_sources(self) -> tuple[np.ndarray, np.ndarray]:
        """Packed loop sources: ``src`` (S, 6) and ``coil`` (S,), see :mod:`.kernels`."""
        if self._loops is not None:
            return self._loops
        p = self.params
        rows, coil = [], []
        if self.options.field == 'fast':
            mags = p.permanent_magnets
            for j in range(mags.count):
                current = mags.polarization[j] * mags.length[j] / MU0
                rows.append([*mags.centers[j], mags.radius[j], current, 0.0])
                coil.append(-1)
            sol = p.solenoids
            c = self.correction
            for j in range(sol.count):
                rows.append([*sol.centers[j], c * sol.radius[j], 0.0, sol.turns[j]])
                coil.append(j)
        elif self.options.field == 'filament':
            sol = p.solenoids
            for j in range(sol.count):
                heights, radii = filament_loops(sol.radius[j], sol.length[j], sol.turns[j])
                cx, cy, cz = sol.centers[j]
                for dz in heights:
                    for r in radii:
                        rows.append([cx, cy, cz + dz, r, 0.0, 1.0])
                        coil.append(j)
        self._loops = (np.array(rows, dtype=float).reshape(-1, 6), np.array(coil, dtype=np.int64))
        return self._loops

    # ------------------------------------------------------------------ field
    def field_at(self, points, u=None) -> np.ndarray:
        """Field of the base (magnets and solenoids) at world points.

        Parameters
        ----------
        points : array_like, shape (n, 3)
            Points in the world frame, m.
        u : array_like, shape (n_s,), optional
            Solenoid currents, A (default zero).

        Returns
        -------
        ndarray, shape (n, 3)
            Flux density, T.
        """
        pts = as_points(points)
        current = self._inputs(u)
        src, coil = self._loop_sources()
        out = kernels.loops_field(pts, current, src, coil)
        if self.options.field != 'fast':
            p = self.params
            mags = p.permanent_magnets
            for j in range(mags.count):
                out += sheet_field(
                    pts - mags.centers[j],
                    mags.radius[j],
                    mags.length[j],
                    mags.polarization[j] * mags.length[j] / MU0,
                )
            if self.options.field == 'accurate':
                sol = p.solenoids
                for j in range(sol.count):
                    if current[j] != 0.0:
                        out += sheet_field(
                            pts - sol.centers[j],
                            sol.radius[j],
                            sol.length[j],
                            sol.turns[j] * current[j],
                        )
        return out

    @property
    def magnet_loop_current(self) -> float:
        """Current of the fast model's loop for the levitating magnet's own field, A.

        ``-J l / (2 mu0)``: half the magnet's equivalent current, as published
        (the accurate/filament models use the full sheet current ``-J l / mu0``).
        """
        m = self.params.magnet
        return -m.polarization * m.thickness / (2.0 * MU0)

    def magnet_field_at(self, points, x) -> np.ndarray:
        """Field of the levitating magnet at world points, T, shape (n, 3).

        Fast model: a loop of radius R with current ``-J l / (2 mu0)``, half the
        magnet's equivalent current, as published. Accurate/filament: the exact
        current sheet (``-J l / mu0``).

        Parameters
        ----------
        points : array_like, shape (n, 3)
            World points, m.
        x : array_like, shape (12,)
            State of the magnet.
        """
        pts = as_points(points)
        state = self._state(x)
        r = kernels.rotation_matrix(state[3], state[4], state[5])
        local = (pts - state[:3]) @ r  # rows: R^T (s - p)
        m = self.params.magnet
        if self.options.field == 'fast':
            b_local = loop_field(local, m.radius, self.magnet_loop_current)
        else:
            b_local = sheet_field(
                local, m.radius, m.thickness, -m.polarization * m.thickness / MU0
            )
        return b_local @ r.T

    # ------------------------------------------------------------------ force
    def force_and_torque(self, x, u=None) -> tuple[np.ndarray, np.ndarray]:
        """Magnetic force and torque on the levitating magnet (world frame).

        Parameters
        ----------
        x : array_like, shape (12,)
            State (only position and angles are used).
        u : array_like, shape (n_s,), optional
            Solenoid currents, A (default zero).

        Returns
        -------
        force : ndarray, shape (3,)
            N (gravity not included).
        torque : ndarray, shape (3,)
            N m about the magnet's centre.
        """
        wrench = self.wrench(x, u)
        return wrench[:3], wrench[3:]

    def wrench(self, x, u=None) -> np.ndarray:
        """Force and torque stacked, shape (6,): (F (N), tau (N m)), world frame.

        Parameters
        ----------
        x : array_like, shape (12,)
            State of the magnet.
        u : array_like, shape (n_s,), optional
            Solenoid currents, A (default zero).
        """
        state = self._state(x)
        current = self._inputs(u)
        if self.options.field == 'fast':
            src, coil, rim, par, work = self.fast_arguments()
            r = kernels.rotation_matrix(state[3], state[4], state[5])
            return kernels.rim_force_torque(state, current, src, coil, rim, par, work, r)
        return self._surface_wrench(state, current)

    def _surface_wrench(self, state: np.ndarray, current: np.ndarray) -> np.ndarray:
        """Rim-surface quadrature (accurate/filament): trapezoid around and across."""
        m = self.params.magnet
        n_ax = self.options.axial_points
        heights = (
            np.linspace(-m.thickness / 2, m.thickness / 2, n_ax) if n_ax > 1 else (np.zeros(1))
        )
        w_ax = np.full(n_ax, m.thickness / max(n_ax - 1, 1))
        if n_ax > 1:
            w_ax[[0, -1]] *= 0.5
        else:
            w_ax[:] = m.thickness
        r = kernels.rotation_matrix(state[3], state[4], state[5])
        c = np.tile(self._cos, n_ax)
        s = np.tile(self._sin, n_ax)
        h = np.repeat(heights, self.rim_points)
        offsets = np.column_stack([m.radius * c, m.radius * s, h]) @ r.T
        tangents = np.column_stack([-s, c, np.zeros_like(c)]) @ r.T
        field = self.field_at(state[:3] + offsets, current)
        weights = np.repeat(w_ax, self.rim_points) * m.radius * 2.0 * np.pi / self.rim_points
        elements = self.k0 * np.cross(tangents, field) * weights[:, None]
        force = elements.sum(axis=0)
        if self._torque_mode == kernels.TORQUE_TRUE:
            torque = np.cross(offsets, elements).sum(axis=0)
        else:
            torque = (self.k0 * np.cross(r[:, 2], field) * weights[:, None]).sum(axis=0)
        return np.concatenate([force, torque])

    # ------------------------------------------------------------------ f and h
    def dynamics(self, x, u=None) -> np.ndarray:
        """f(x, u): time derivative of the state, shape (12,).

        Parameters
        ----------
        x : array_like, shape (12,)
            State.
        u : array_like, shape (n_s,), optional
            Solenoid currents, A.
        """
        state = self._state(x)
        m = self.params.magnet
        if self.options.field == 'fast':
            return kernels.fast_dynamics(state, self._inputs(u), *self.fast_arguments())
        return kernels.rigid_body_rates(
            state,
            self.wrench(state, u),
            m.mass,
            self._inertia,
            self._kinematics,
            kernels.rotation_matrix(state[3], state[4], state[5]),
        )

    def measurement(self, x, u=None, with_magnet: bool = True) -> np.ndarray:
        """h(x, u): sensor readings [Bx_0, By_0, Bz_0, Bx_1, ...], T, shape (3 n_sensors,).

        Each sensor reads the base field (including the solenoids' direct
        feedthrough) plus the levitating magnet's field, through its mounting
        rotation, gain and offset.

        Parameters
        ----------
        x : array_like, shape (12,)
            State (the magnet's pose matters).
        u : array_like, shape (n_s,), optional
            Solenoid currents, A.
        with_magnet : bool
            False leaves the levitating magnet out (a base without a magnet).
        """
        state = self._state(x)
        current = self._inputs(u)
        if self.options.field == 'fast':
            src, coil, sens, mag, work = self.measurement_arguments()
            if not with_magnet:
                mag = np.array([mag[0], 0.0])
            return kernels.fast_measurement(state, current, src, coil, sens, mag, work)
        pos = self._sensor_pos
        total = self.field_at(pos, current)
        if with_magnet:
            total = total + self.magnet_field_at(pos, state)
        local = np.einsum('kji,kj->ki', self._sensor_rot, total)
        return (self._sensor_gain * local + self._sensor_offset).ravel()

    # ------------------------------------------------------------------ kernel arguments
    def fast_arguments(self) -> tuple:
        """Packed arguments (src, coil, rim, par, work) of the fast-model kernels.

        See :mod:`maglev_ros.physics.kernels` for the layout; fast model only.
        """
        if self._fast_args is None:
            m = self.params.magnet
            src, coil = self._loop_sources()
            rim = np.ascontiguousarray(np.vstack([self._cos, self._sin]))
            scale = m.radius * m.thickness * 2.0 * np.pi / self.rim_points
            par = np.array(
                [
                    m.radius,
                    scale,
                    self.k0,
                    m.mass,
                    *self._inertia,
                    self._torque_mode,
                    self._kinematics,
                ],
                dtype=float,
            )
            self._fast_args = (src, coil, rim, par, self._workspace())
        return self._fast_args

    def measurement_arguments(self) -> tuple:
        """Packed arguments (src, coil, sens, mag, work) of :func:`kernels.fast_measurement`."""
        if self._measurement_args is None:
            m = self.params.magnet
            src, coil = self._loop_sources()
            k = len(self.params.sensors)
            sens = np.hstack(
                [
                    self._sensor_pos,
                    self._sensor_rot.reshape(k, 9),
                    self._sensor_gain,
                    self._sensor_offset,
                ]
            ).reshape(k, 18)
            mag = np.array([m.radius, self.magnet_loop_current])
            self._measurement_args = (
                src,
                coil,
                np.ascontiguousarray(sens),
                mag,
                self._workspace(),
            )
        return self._measurement_args

    def _workspace(self) -> np.ndarray:
        """Scratch array for the compiled kernels (one per model, reused)."""
        if self._work is None:
            n_src = self._loop_sources()[0].shape[0]
            width = max(self.rim_points, len(self.params.sensors)) * max(n_src, 1)
            self._work = np.empty((kernels.WORK_ROWS, width))
        return self._work

    # ------------------------------------------------------------------ helpers
    def _state(self, x) -> np.ndarray:
        state = np.asarray(x, dtype=float)
        if state.shape != (12,):
            raise ValueError(f'state x must have shape (12,), got {state.shape}')
        return np.ascontiguousarray(state)

    def _inputs(self, u) -> np.ndarray:
        if u is None:
            return np.zeros(self.n_inputs)
        current = np.ascontiguousarray(np.asarray(u, dtype=float))
        if current.shape != (self.n_inputs,):
            raise ValueError(f'input u must have shape ({self.n_inputs},), got {current.shape}')
        return current

    def with_options(self, **changes) -> MaggyModel:
        """Return a model of the same parameters with some options changed.

        Parameters
        ----------
        **changes : object
            :class:`ModelOptions` fields to change.
        """
        return MaggyModel(self.params, dataclasses.replace(self.options, **changes))

    def inverted(self) -> MaggyModel:
        """Return the same model with the levitating magnet flipped (J -> -J)."""
        magnet = dataclasses.replace(
            self.params.magnet, polarization=-self.params.magnet.polarization
        )
        model = MaggyModel(self.params.replace(magnet=magnet), self.options)
        if self.options.field == 'fast':
            model._correction = self.correction
        return model

    def hover_state(self, z: float) -> np.ndarray:
        """Return the centred, level, resting state at height ``z`` (m), shape (12,).

        Parameters
        ----------
        z : float
            Height of the magnet's centre, m.
        """
        x = np.zeros(12)
        x[2] = z
        return x

    def __repr__(self) -> str:
        o = self.options
        return (
            f'MaggyModel({self.params.name}, field={o.field}, torque={o.torque}, '
            f'kinematics={o.kinematics}, rim_points={self.rim_points})'
        )


def make_model(params: str | MaggyParameters = 'maggy_v2', **options) -> MaggyModel:
    """Build a model from a preset name, a YAML path or a parameter set.

    Parameters
    ----------
    params : str or MaggyParameters
        ``maggy_v2``, ``maggy_v4``, a YAML path, or a loaded set.
    **options
        Fields of :class:`ModelOptions`.
    """
    if not isinstance(params, MaggyParameters):
        params = load_parameters(params)
    return MaggyModel(params, ModelOptions(**options))


#: Current in every solenoid when matching the fast model to the filament model, A.
CORRECTION_TEST_CURRENT = 100.0


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
        No equilibrium, or no factor in [0.05, 3] matches.
    """
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
        f'{params.name}: no solenoid radius factor in [0.05, 3] matches the filament model'
    )
