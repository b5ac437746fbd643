"""The physics model's parameters as a named vector: unit, nominal, bounds, free or fixed.

A :class:`ParameterVector` is built from a :class:`~maglev_ros.physics.MaggyParameters`
set (:func:`parameter_vector`). Each entry is a :class:`ParameterSpec`; its
value maps onto the parameter file's schema, so a calibrated vector becomes a
parameter set (:meth:`ParameterVector.apply`) that the simulator, the
estimator and the controller load like ``maggy_v2.yaml``.

Names (``k`` a sensor, ``j`` a solenoid or a permanent magnet, ``e`` a
fixed-magnet experiment):

=========================== ====== =====================================================
``magnet.polarization``     T      levitating magnet (negative by the sign convention)
``magnet.mass``             kg     levitating magnet (dynamic data only)
``pm{j}.polarization``      T      permanent magnet ``j``
``coil{j}.gain``            1      solenoid ``j``: effective turns / nominal turns
``solenoid_radius_correction`` 1   fast model's solenoid radius factor
``coils.resistance``        ohm    every coil (dynamic data only)
``sensor{k}.x|y|z``         m      sensor position
``sensor{k}.gain_x|y|z``    1      per-axis gain
``sensor{k}.offset_x|y|z``  T      per-axis offset
``sensor{k}.tilt_x|y|z``    rad    mounting rotation (rotation vector, after the nominal one)
``pose{e}.x|y|z|alpha|beta`` m/rad where experiment ``e`` held the magnet (not in the file)
``board.b{x|y|z}_{x|y}pair`` T/A   a V4x PC-control board's processed field per ampere of
                                   its x or y coil pair (``--measurement board``; not in
                                   the file)
=========================== ====== =====================================================

The sensor delay is not a continuous parameter here: static calibration
estimates it as a whole number of samples per experiment
(:func:`maglev_ros.greybox.static.best_delay`).
"""

from __future__ import annotations

import dataclasses
import fnmatch
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..physics.parameters import (
    MaggyParameters,
    PermanentMagnets,
    Sensor,
    Solenoids,
)
from .errors import GreyBoxError

__all__ = [
    'ParameterSpec',
    'ParameterVector',
    'parameter_vector',
    'BOARD_PAIRS',
    'POSE_NAMES',
]

#: Pose coordinates of a held magnet (gamma is left out: an axisymmetric magnet
#: looks the same at any yaw).
POSE_NAMES = ('x', 'y', 'z', 'alpha', 'beta')
_AXES = ('x', 'y', 'z')
#: A board's processed field per ampere of each coil pair, row by row (Bx, By, Bz; x, y pair)
BOARD_PAIRS = tuple(f'board.b{a}_{p}pair' for a in _AXES for p in ('x', 'y'))
#: T/A either side of the measured value that a board's pair feedthrough may take
BOARD_PAIR_SPAN = 2e-4


@dataclass(frozen=True)
class ParameterSpec:
    """One named parameter.

    Attributes
    ----------
    name : str
        Name (see the module's table).
    unit : str
        SI unit of ``nominal``, ``lower`` and ``upper``.
    nominal : float
        Value in the parameter set the vector was built from.
    lower, upper : float
        Bounds (``lower <= nominal <= upper``).
    free : bool
        Estimated (True) or held at ``nominal``.
    scale : float
        Typical size of a change, same unit (scales the optimiser's steps and
        the identifiability analysis).
    display_unit : str
        Unit for people (``mm``, ``mT``, ...).
    display_factor : float
        SI value times this factor is the value in ``display_unit``.
    description : str
        What it is.
    in_file : bool
        True when the value goes into the parameter file (False: an
        experiment's parameter, such as where the magnet was held).
    """

    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    free: bool = False
    scale: float = 1.0
    display_unit: str = ''
    display_factor: float = 1.0
    description: str = ''
    in_file: bool = True

    def display(self, value: float) -> str:
        """``value`` (SI) formatted in the display unit, e.g. ``'0.125 mm'``.

        Parameters
        ----------
        value : float
            Value in SI units.
        """
        unit = self.display_unit or ('' if self.unit == '1' else self.unit)
        return f'{value * self.display_factor:.6g} {unit}'.rstrip()


def _spec(name, unit, nominal, lower, upper, scale, display=('', 1.0), text='', in_file=True):
    return ParameterSpec(
        name=name,
        unit=unit,
        nominal=float(nominal),
        lower=float(lower),
        upper=float(upper),
        scale=float(scale),
        display_unit=display[0],
        display_factor=display[1],
        description=text,
        in_file=in_file,
    )


def _relative(name, unit, nominal, spread, scale, text, display=('', 1.0)):
    lo, hi = sorted((nominal * (1 - spread), nominal * (1 + spread)))
    return _spec(name, unit, nominal, lo, hi, scale, display, text)


def _board_specs(params: MaggyParameters, correction: float) -> list[ParameterSpec]:
    m = params.magnet
    specs = [
        _relative('magnet.polarization', 'T', m.polarization, 0.3, 0.01, 'levitating magnet J'),
        _relative('magnet.mass', 'kg', m.mass, 0.5, 0.001, 'levitating magnet', ('g', 1e3)),
    ]
    pm = params.permanent_magnets
    for j in range(pm.count):
        specs.append(
            _relative(
                f'pm{j}.polarization', 'T', pm.polarization[j], 0.3, 0.01, f'permanent magnet {j}'
            )
        )
    for j in range(params.solenoids.count):
        specs.append(_spec(f'coil{j}.gain', '1', 1.0, 0.5, 1.5, 0.01, text=f'solenoid {j} gain'))
    specs.append(
        _spec(
            'solenoid_radius_correction',
            '1',
            correction,
            0.5 * correction,
            min(1.5, 1.5 * correction),
            0.01,
            text='fast-model solenoid radius factor',
        )
    )
    r = params.coils.resistance
    specs.append(_relative('coils.resistance', 'ohm', r, 0.75, 0.05, 'coil resistance'))
    for k, sensor in enumerate(params.sensors):
        for a, axis in enumerate(_AXES):
            p = sensor.position[a]
            specs.append(
                _spec(
                    f'sensor{k}.{axis}',
                    'm',
                    p,
                    p - 0.003,
                    p + 0.003,
                    1e-4,
                    ('mm', 1e3),
                    f'sensor {k} position',
                )
            )
        for a, axis in enumerate(_AXES):
            g = sensor.gain[a]
            specs.append(
                _spec(f'sensor{k}.gain_{axis}', '1', g, 0.5 * g, 1.5 * g, 0.01, text='gain')
            )
        for a, axis in enumerate(_AXES):
            o = sensor.offset[a]
            specs.append(
                _spec(
                    f'sensor{k}.offset_{axis}',
                    'T',
                    o,
                    o - 0.02,
                    o + 0.02,
                    1e-4,
                    ('mT', 1e3),
                    f'sensor {k} offset',
                )
            )
        for axis in _AXES:
            specs.append(
                _spec(
                    f'sensor{k}.tilt_{axis}',
                    'rad',
                    0.0,
                    -0.3,
                    0.3,
                    0.01,
                    ('mrad', 1e3),
                    f'sensor {k} mounting rotation',
                )
            )
    return specs


def _pose_specs(index: int, pose: Sequence[float]) -> list[ParameterSpec]:
    specs = []
    for name, value in zip(POSE_NAMES, pose, strict=True):
        angle = name in ('alpha', 'beta')
        spread = 0.2 if angle else (0.01 if name == 'z' else 0.005)
        specs.append(
            _spec(
                f'pose{index}.{name}',
                'rad' if angle else 'm',
                value,
                value - spread,
                value + spread,
                0.01 if angle else 1e-4,
                ('mrad', 1e3) if angle else ('mm', 1e3),
                f'held magnet, experiment {index}',
                in_file=False,
            )
        )
    return specs


def _board_pair_specs(pairs: np.ndarray) -> list[ParameterSpec]:
    return [
        _spec(
            name,
            'T/A',
            value,
            value - BOARD_PAIR_SPAN,
            value + BOARD_PAIR_SPAN,
            1e-5,
            ('mT/A', 1e3),
            "board's processed field per ampere of a coil pair",
            in_file=False,
        )
        for name, value in zip(BOARD_PAIRS, np.ravel(pairs), strict=True)
    ]


class ParameterVector:
    """An ordered set of named parameters over a base parameter set.

    Parameters
    ----------
    base : MaggyParameters
        The nominal set (what fixed parameters keep and what the file's other
        fields are copied from).
    specs : sequence of ParameterSpec
        The entries, in order.
    """

    def __init__(self, base: MaggyParameters, specs: Sequence[ParameterSpec]):
        self.base = base
        self.specs = tuple(specs)
        self._index = {s.name: i for i, s in enumerate(self.specs)}
        if len(self._index) != len(self.specs):
            raise GreyBoxError('parameter names must be unique')

    # ------------------------------------------------------------------ access
    @property
    def names(self) -> tuple[str, ...]:
        """Every name, in order."""
        return tuple(s.name for s in self.specs)

    @property
    def free_names(self) -> tuple[str, ...]:
        """Names of the free parameters, in order."""
        return tuple(s.name for s in self.specs if s.free)

    @property
    def free_specs(self) -> tuple[ParameterSpec, ...]:
        """Specs of the free parameters, in order."""
        return tuple(s for s in self.specs if s.free)

    @property
    def nominal(self) -> dict[str, float]:
        """Every nominal value by name."""
        return {s.name: s.nominal for s in self.specs}

    def __getitem__(self, name: str) -> ParameterSpec:
        return self.specs[self._lookup(name)]

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __len__(self) -> int:
        return len(self.specs)

    def _lookup(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise GreyBoxError(
                f'unknown parameter {name!r} (e.g. {", ".join(self.names[:6])}, ...; '
                '--list shows all)'
            ) from None

    def expand(self, patterns: Iterable[str]) -> tuple[str, ...]:
        """Names matching shell-style patterns (``sensor*.offset_*``), in vector order.

        Parameters
        ----------
        patterns : iterable of str
            Shell-style name patterns.

        Raises
        ------
        GreyBoxError
            A pattern matches no parameter.
        """
        chosen = set()
        for pattern in patterns:
            hits = [n for n in self.names if fnmatch.fnmatchcase(n, pattern)]
            if not hits:
                raise GreyBoxError(
                    f'no parameter matches {pattern!r} (e.g. {", ".join(self.names[:6])}, '
                    '...; --list shows all)'
                )
            chosen.update(hits)
        return tuple(n for n in self.names if n in chosen)

    # ------------------------------------------------------------------ changes
    def with_free(self, patterns: Iterable[str]) -> ParameterVector:
        """Return a copy whose free set is exactly the parameters matching ``patterns``.

        Parameters
        ----------
        patterns : iterable of str
            Shell-style patterns of the parameters to free.
        """
        chosen = set(self.expand(patterns))
        specs = [dataclasses.replace(s, free=s.name in chosen) for s in self.specs]
        return ParameterVector(self.base, specs)

    def with_bounds(self, name: str, lower: float, upper: float) -> ParameterVector:
        """Return a copy with other bounds for ``name`` (SI units).

        Parameters
        ----------
        name : str
            The parameter.
        lower, upper : float
            New bounds, SI units.

        Raises
        ------
        GreyBoxError
            Unknown name, or bounds that are not ordered or exclude the nominal value.
        """
        spec = self[name]
        if not (np.isfinite(lower) and np.isfinite(upper) and lower < upper):
            raise GreyBoxError(
                f'bounds of {name} must be finite with lower < upper, got [{lower:g}, {upper:g}]'
            )
        if not lower <= spec.nominal <= upper:
            unit = '' if spec.unit == '1' else f' {spec.unit}'
            raise GreyBoxError(
                f'bounds [{lower:g}, {upper:g}]{unit} of {name} exclude its nominal '
                f'value {spec.nominal:g}{unit}'
            )
        specs = list(self.specs)
        specs[self._lookup(name)] = dataclasses.replace(spec, lower=lower, upper=upper)
        return ParameterVector(self.base, specs)

    def with_nominal(self, values: Mapping[str, float]) -> ParameterVector:
        """Return a copy with other nominal values (bounds widened to hold them).

        Parameters
        ----------
        values : mapping of str to float
            New nominal values by name, SI.
        """
        specs = list(self.specs)
        for name, value in values.items():
            i = self._lookup(name)
            s = specs[i]
            specs[i] = dataclasses.replace(
                s, nominal=float(value), lower=min(s.lower, value), upper=max(s.upper, value)
            )
        return ParameterVector(self.base, specs)

    def with_pose(self, index: int, pose: Sequence[float], free: bool = True) -> ParameterVector:
        """Return a copy with the pose parameters of fixed-magnet experiment ``index``.

        Parameters
        ----------
        index : int
            Experiment number (names ``pose{index}.x`` ...).
        pose : sequence of float
            x, y, z (m), alpha, beta (rad): where the magnet is held (a guess).
        free : bool
            Estimate the pose (default) or hold it.
        """
        new = [dataclasses.replace(s, free=free) for s in _pose_specs(index, pose)]
        kept = [s for s in self.specs if not s.name.startswith(f'pose{index}.')]
        return ParameterVector(self.base, [*kept, *new])

    def with_board_pairs(
        self, pairs, free: Iterable[str] = ('board.bx_xpair', 'board.by_ypair')
    ) -> ParameterVector:
        """Return a copy with a board's pair feedthrough as parameters (:data:`BOARD_PAIRS`).

        Parameters
        ----------
        pairs : array_like, shape (3, 2)
            Processed Bx, By, Bz per ampere of the x and the y pair, T/A (the
            nominal values: measured, or the model's own).
        free : iterable of str
            Which are estimated (default each axis's own pair: what the
            firmware's compensation leaves).
        """
        pairs = np.asarray(pairs, dtype=float)
        if pairs.shape != (3, 2) or not np.all(np.isfinite(pairs)):
            raise GreyBoxError(f'board pairs must be finite, shape (3, 2), got {pairs.shape}')
        free = set(free)
        new = [dataclasses.replace(s, free=s.name in free) for s in _board_pair_specs(pairs)]
        kept = [s for s in self.specs if not s.name.startswith('board.')]
        return ParameterVector(self.base, [*kept, *new])

    def board_pairs(self, values: Mapping[str, float]) -> np.ndarray | None:
        """Return the board's pair feedthrough (3, 2) in ``values``, T/A (None: not a parameter).

        Parameters
        ----------
        values : mapping of str to float
            Parameter values by name.
        """
        if BOARD_PAIRS[0] not in self._index:
            return None
        merged = {**self.nominal, **values}
        return np.array([merged[n] for n in BOARD_PAIRS]).reshape(3, 2)

    # ------------------------------------------------------------------ values
    def values(self, free_values: Sequence[float] | None = None) -> dict[str, float]:
        """Every value by name: nominal, with the free ones replaced by ``free_values``.

        Parameters
        ----------
        free_values : sequence of float, optional
            Values of the free parameters, in order (None: nominal).
        """
        out = self.nominal
        if free_values is not None:
            names = self.free_names
            if len(free_values) != len(names):
                raise GreyBoxError(
                    f'expected {len(names)} free values ({", ".join(names)}), '
                    f'got {len(free_values)}'
                )
            out.update(zip(names, (float(v) for v in free_values), strict=True))
        return out

    def pose(self, index: int, values: Mapping[str, float]) -> np.ndarray:
        """Return the 12-state of fixed-magnet experiment ``index`` from ``values``.

        Parameters
        ----------
        index : int
            Experiment number.
        values : mapping of str to float
            Parameter values by name (holding ``pose{index}.*``).
        """
        x = np.zeros(12)
        for i, name in enumerate(POSE_NAMES):
            x[(0, 1, 2, 3, 4)[i]] = values[f'pose{index}.{name}']
        return x

    def apply(self, values: Mapping[str, float]) -> MaggyParameters:
        """Return the parameter set with ``values`` (by name; others from the base set).

        The solenoid radius correction is always written out (so a changed
        coil never triggers the slow filament computation); coil gains become
        effective turns (``turns * gain``).

        Parameters
        ----------
        values : mapping of str to float
            Parameter values by name, SI.
        """
        p = self.base
        get = {**self.nominal, **values}.__getitem__
        m = p.magnet
        magnet = dataclasses.replace(
            m, polarization=get('magnet.polarization'), mass=get('magnet.mass')
        )
        pm = p.permanent_magnets
        magnets = PermanentMagnets(
            pm.centers,
            pm.radius,
            pm.length,
            _frozen([get(f'pm{j}.polarization') for j in range(pm.count)]),
        )
        sol = p.solenoids
        solenoids = Solenoids(
            sol.centers,
            sol.radius,
            sol.length,
            _frozen([sol.turns[j] * get(f'coil{j}.gain') for j in range(sol.count)]),
        )
        sensors = []
        for k, s in enumerate(p.sensors):
            tilt = [get(f'sensor{k}.tilt_{a}') for a in _AXES]
            rotation = s.rotation
            if any(tilt):
                rotation = s.rotation @ Rotation.from_rotvec(tilt).as_matrix()
            sensors.append(
                Sensor(
                    position=_frozen([get(f'sensor{k}.{a}') for a in _AXES]),
                    rotation=_frozen(rotation),
                    gain=_frozen([get(f'sensor{k}.gain_{a}') for a in _AXES]),
                    offset=_frozen([get(f'sensor{k}.offset_{a}') for a in _AXES]),
                )
            )
        coils = dataclasses.replace(p.coils, resistance=get('coils.resistance'))
        return p.replace(
            magnet=magnet,
            permanent_magnets=magnets,
            solenoids=solenoids,
            sensors=tuple(sensors),
            coils=coils,
            solenoid_radius_correction=get('solenoid_radius_correction'),
        )


def _frozen(values) -> np.ndarray:
    out = np.array(values, dtype=float)
    out.setflags(write=False)
    return out


def parameter_vector(params: MaggyParameters, correction: float | None = None) -> ParameterVector:
    """Return the named parameter vector of a parameter set, every parameter fixed.

    Parameters
    ----------
    params : MaggyParameters
        The nominal set.
    correction : float, optional
        Its solenoid radius correction (default: the file's value, else the
        fast model's computed one).

    Returns
    -------
    ParameterVector
    """
    if correction is None:
        if params.solenoid_radius_correction is not None:
            correction = float(params.solenoid_radius_correction)
        else:
            from ..physics.model import MaggyModel

            correction = MaggyModel(params).correction
    return ParameterVector(params, _board_specs(params, float(correction)))
