"""Physics parameter sets of the Maggy platform: typed, immutable, validated.

A parameter set describes the base (solenoids and permanent magnets), the
levitating magnet, the Hall sensors, the workspace box and the coils'
electrical data. It is loaded from a YAML file with its own schema
(``config/maggy_v2.yaml``, ``config/maggy_v4.yaml``); every error names the
file and the key.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..yaml_errors import yaml_error_text

__all__ = [
    'ParameterError',
    'Cylinders',
    'Solenoids',
    'PermanentMagnets',
    'LevitatingMagnet',
    'Sensor',
    'Workspace',
    'Coils',
    'MaggyParameters',
    'PRESETS',
    'load_parameters',
    'parameters_from_mapping',
    'preset_path',
]

PRESETS = ('maggy_v2', 'maggy_v4')


class ParameterError(ValueError):
    """A parameter file or value is invalid; the message names file and key."""


def _frozen(array: Any, dtype: type = float) -> np.ndarray:
    out = np.array(array, dtype=dtype)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class Cylinders:
    """Short vertical cylinders of the base (solenoids or permanent magnets).

    Attributes
    ----------
    centers : ndarray, shape (n, 3)
        Centres of the cylinders in the world frame, m.
    radius : ndarray, shape (n,)
        Radii, m.
    length : ndarray, shape (n,)
        Lengths, m.
    """

    centers: np.ndarray
    radius: np.ndarray
    length: np.ndarray

    @property
    def count(self) -> int:
        """Number of cylinders."""
        return int(self.radius.shape[0])


@dataclass(frozen=True)
class Solenoids(Cylinders):
    """Solenoids of the base (radius physical; the fast model may scale it).

    Attributes
    ----------
    turns : ndarray, shape (n_s,)
        Number of turns of each coil.
    """

    turns: np.ndarray = field(default_factory=lambda: _frozen(np.zeros(0)))


@dataclass(frozen=True)
class PermanentMagnets(Cylinders):
    """Permanent magnets of the base, uniformly magnetised along z.

    Attributes
    ----------
    polarization : ndarray, shape (n_m,)
        Polarisation J along +z, T.
    """

    polarization: np.ndarray = field(default_factory=lambda: _frozen(np.zeros(0)))


@dataclass(frozen=True)
class LevitatingMagnet:
    """The levitating disc magnet.

    Attributes
    ----------
    radius : float
        Disc radius R, m.
    thickness : float
        Disc thickness l, m.
    polarization : float
        Polarisation J, T (negative in the published sets).
    mass : float
        Mass m, kg.
    inertia : ndarray, shape (3,)
        Principal moments (Ixx, Iyy, Izz) in the body frame, kg m^2.
    """

    radius: float
    thickness: float
    polarization: float
    mass: float
    inertia: np.ndarray


@dataclass(frozen=True)
class Sensor:
    """A 3-axis Hall sensor fixed to the base.

    The reading is ``gain * (rotation.T @ B) + offset`` with ``B`` the world-frame
    field at ``position``.

    Attributes
    ----------
    position : ndarray, shape (3,)
        Position in the world frame, m.
    rotation : ndarray, shape (3, 3)
        Mounting rotation, sensor frame to world frame (identity by default).
    gain : ndarray, shape (3,)
        Per-axis gain (1 by default).
    offset : ndarray, shape (3,)
        Per-axis offset, T (0 by default).
    """

    position: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: _frozen(np.eye(3)))
    gain: np.ndarray = field(default_factory=lambda: _frozen(np.ones(3)))
    offset: np.ndarray = field(default_factory=lambda: _frozen(np.zeros(3)))


@dataclass(frozen=True)
class Workspace:
    """Axis-aligned box the magnet's centre must stay in, m (world frame)."""

    lower: np.ndarray
    upper: np.ndarray


@dataclass(frozen=True)
class Coils:
    """Electrical data of the solenoids (all coils alike).

    Attributes
    ----------
    resistance : float
        Coil resistance, ohm.
    inductance : float
        Coil inductance, H.
    supply_voltage : float
        H-bridge supply, V: the largest voltage magnitude a coil can see.
    """

    resistance: float
    inductance: float
    supply_voltage: float


@dataclass(frozen=True)
class MaggyParameters:
    """A complete, validated physics parameter set.

    Attributes
    ----------
    name : str
        Set name (``maggy_v2``, ...).
    solenoids : Solenoids
    permanent_magnets : PermanentMagnets
    magnet : LevitatingMagnet
    sensors : tuple of Sensor
    workspace : Workspace
    coils : Coils
    solenoid_radius_correction : float or None
        Override of the fast model's solenoid radius factor; None computes it.
    source : str
        Where the set came from (file path), for messages.
    """

    name: str
    solenoids: Solenoids
    permanent_magnets: PermanentMagnets
    magnet: LevitatingMagnet
    sensors: tuple[Sensor, ...]
    workspace: Workspace
    coils: Coils
    solenoid_radius_correction: float | None = None
    source: str = '<memory>'

    def replace(self, **changes: Any) -> MaggyParameters:
        """Return a copy with some fields replaced (the object is immutable).

        Parameters
        ----------
        **changes : object
            Fields to replace.
        """
        return dataclasses.replace(self, **changes)

    def with_inertia(self, inertia: Any) -> MaggyParameters:
        """Return a copy whose levitating magnet has other principal moments, kg m^2.

        Parameters
        ----------
        inertia : array_like, shape (3,)
            Principal moments, kg m^2.
        """
        values = _frozen(inertia)
        if values.shape != (3,) or not np.all(values > 0):
            raise ParameterError(f'inertia must be 3 positive numbers, got {inertia!r}')
        return self.replace(magnet=dataclasses.replace(self.magnet, inertia=values))

    def without_base(self) -> MaggyParameters:
        """Return a copy with no solenoids, magnets or sensors (gravity only)."""
        empty = _frozen(np.zeros((0, 3)))
        none = _frozen(np.zeros(0))
        return self.replace(
            solenoids=Solenoids(empty, none, none, none),
            permanent_magnets=PermanentMagnets(empty, none, none, none),
            sensors=(),
        )

    @property
    def base_top(self) -> float:
        """Height of the top of the tallest base component, m."""
        tops = [0.0]
        for cyl in (self.solenoids, self.permanent_magnets):
            if cyl.count:
                tops.append(float(np.max(cyl.centers[:, 2] + cyl.length / 2)))
        return max(tops)


# --------------------------------------------------------------------------- loading

_TOP_KEYS = {
    'name': False,
    'solenoids': True,
    'permanent_magnets': True,
    'levitating_magnet': True,
    'sensors': True,
    'workspace': True,
    'coils': True,
    'solenoid_radius_correction': False,
}
_CYLINDER_KEYS = ('x', 'y', 'z', 'radius', 'length')


class _Reader:
    """Validates one mapping level, with the file name and key path in errors."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, problem: str) -> ParameterError:
        where = f'{self.source}: {key}' if key else self.source
        return ParameterError(f'{where}: {problem}')

    def mapping(self, value: Any, key: str, allowed: Mapping[str, bool]) -> dict:
        if not isinstance(value, Mapping):
            raise self.fail(key, f'expected a mapping, got {type(value).__name__}')
        for name in value:
            if name not in allowed:
                raise self.fail(
                    f'{key}.{name}' if key else str(name),
                    f'unknown key (allowed: {", ".join(sorted(allowed))})',
                )
        for name, required in allowed.items():
            if required and name not in value:
                raise self.fail(f'{key}.{name}' if key else name, 'missing key')
        return dict(value)

    def number(self, value: Any, key: str, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, f'expected a number, got {value!r}')
        number = float(value)
        if not np.isfinite(number):
            raise self.fail(key, f'must be finite, got {value!r}')
        if positive and number <= 0:
            raise self.fail(key, f'must be positive, got {value!r}')
        return number

    def vector(self, value: Any, key: str, length: int | None, positive: bool = False):
        if not isinstance(value, (list, tuple)):
            raise self.fail(key, f'expected a list, got {value!r}')
        if length is not None and len(value) != length:
            raise self.fail(key, f'expected {length} values, got {len(value)}')
        numbers = [self.number(v, f'{key}[{i}]', positive) for i, v in enumerate(value)]
        return _frozen(numbers)


def _cylinders(reader: _Reader, value: Any, key: str, extra: str) -> tuple:
    allowed = {name: True for name in (*_CYLINDER_KEYS, extra)}
    data = reader.mapping(value, key, allowed)
    first = _CYLINDER_KEYS[0]
    raw = data[first]
    if not isinstance(raw, (list, tuple)) or not raw:
        raise reader.fail(f'{key}.{first}', f'expected a non-empty list, got {raw!r}')
    count = len(raw)
    columns = {}
    for name in (*_CYLINDER_KEYS, extra):
        raw = data[name]
        if isinstance(raw, (list, tuple)) and len(raw) != count:
            raise reader.fail(
                f'{key}.{name}',
                f'expected {count} values (as many as {key}.{first}), got {len(raw)}',
            )
        positive = name in ('radius', 'length', 'turns')
        columns[name] = reader.vector(raw, f'{key}.{name}', count, positive)
    centers = _frozen(np.column_stack([columns['x'], columns['y'], columns['z']]))
    return centers, columns['radius'], columns['length'], columns[extra]


def _sensor(reader: _Reader, value: Any, key: str) -> Sensor:
    allowed = {'position': True, 'rotation': False, 'gain': False, 'offset': False}
    data = reader.mapping(value, key, allowed)
    position = reader.vector(data['position'], f'{key}.position', 3)
    rotation = _frozen(np.eye(3))
    if 'rotation' in data:
        rows = data['rotation']
        if not isinstance(rows, (list, tuple)) or len(rows) != 3:
            raise reader.fail(f'{key}.rotation', 'expected a 3x3 matrix (3 rows of 3)')
        rotation = _frozen(
            [reader.vector(r, f'{key}.rotation[{i}]', 3) for i, r in enumerate(rows)]
        )
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) or (
            np.linalg.det(rotation) <= 0
        ):
            raise reader.fail(f'{key}.rotation', 'must be a proper rotation matrix')
    gain = reader.vector(data.get('gain', [1.0] * 3), f'{key}.gain', 3)
    offset = reader.vector(data.get('offset', [0.0] * 3), f'{key}.offset', 3)
    return Sensor(position, rotation, gain, offset)


def parameters_from_mapping(data: Any, source: str = '<memory>') -> MaggyParameters:
    """Validate a parsed parameter document and build the typed parameter set.

    Parameters
    ----------
    data : mapping
        The parsed YAML document (schema as in ``config/maggy_v2.yaml``).
    source : str
        Name used in error messages (usually the file path).

    Returns
    -------
    MaggyParameters

    Raises
    ------
    ParameterError
        Missing, unknown or malformed key; wrong list length; non-positive radius,
        length, turns, mass, thickness or inertia. The message names source and key.
    """
    reader = _Reader(source)
    doc = reader.mapping(data, '', _TOP_KEYS)
    name = doc.get('name', Path(source).stem)
    if not isinstance(name, str) or not name:
        raise reader.fail('name', f'expected a non-empty string, got {name!r}')

    centers, radius, length, turns = _cylinders(reader, doc['solenoids'], 'solenoids', 'turns')
    solenoids = Solenoids(centers, radius, length, turns)
    centers, radius, length, pol = _cylinders(
        reader, doc['permanent_magnets'], 'permanent_magnets', 'polarization'
    )
    magnets = PermanentMagnets(centers, radius, length, pol)

    keys = ('radius', 'thickness', 'polarization', 'mass', 'inertia')
    mdata = reader.mapping(
        doc['levitating_magnet'], 'levitating_magnet', dict.fromkeys(keys, True)
    )
    magnet = LevitatingMagnet(
        radius=reader.number(mdata['radius'], 'levitating_magnet.radius', positive=True),
        thickness=reader.number(mdata['thickness'], 'levitating_magnet.thickness', True),
        polarization=reader.number(mdata['polarization'], 'levitating_magnet.polarization'),
        mass=reader.number(mdata['mass'], 'levitating_magnet.mass', positive=True),
        inertia=reader.vector(mdata['inertia'], 'levitating_magnet.inertia', 3, positive=True),
    )
    if magnet.polarization == 0:
        raise reader.fail('levitating_magnet.polarization', 'must be non-zero')

    raw_sensors = doc['sensors']
    if not isinstance(raw_sensors, (list, tuple)):
        raise reader.fail('sensors', f'expected a list of sensors, got {raw_sensors!r}')
    sensors = tuple(_sensor(reader, s, f'sensors[{i}]') for i, s in enumerate(raw_sensors))

    wdata = reader.mapping(doc['workspace'], 'workspace', {'min': True, 'max': True})
    lower = reader.vector(wdata['min'], 'workspace.min', 3)
    upper = reader.vector(wdata['max'], 'workspace.max', 3)
    if not np.all(upper > lower):
        raise reader.fail('workspace', f'max must exceed min on every axis: {lower} / {upper}')

    ckeys = ('resistance', 'inductance', 'supply_voltage')
    cdata = reader.mapping(doc['coils'], 'coils', dict.fromkeys(ckeys, True))
    coils = Coils(*(reader.number(cdata[k], f'coils.{k}', positive=True) for k in ckeys))

    correction = doc.get('solenoid_radius_correction')
    if correction is not None:
        correction = reader.number(correction, 'solenoid_radius_correction', positive=True)

    return MaggyParameters(
        name=name,
        solenoids=solenoids,
        permanent_magnets=magnets,
        magnet=magnet,
        sensors=sensors,
        workspace=Workspace(lower, upper),
        coils=coils,
        solenoid_radius_correction=correction,
        source=source,
    )


def _config_dirs() -> list[Path]:
    """Places the shipped config files can be, most specific first."""
    dirs = []
    try:  # a colcon/ament install
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory('maglev_ros')) / 'config')
    except Exception:  # noqa: BLE001 - no ament index here: fall through
        pass
    dirs.append(Path(sys.prefix) / 'share' / 'maglev_ros' / 'config')  # pip install
    dirs.append(Path(__file__).resolve().parents[2] / 'config')  # source tree / editable
    return dirs


def preset_path(name: str) -> Path:
    """Return the file of a shipped parameter set (``maggy_v2`` or ``maggy_v4``).

    Parameters
    ----------
    name : str
        ``maggy_v2`` or ``maggy_v4``.

    Raises
    ------
    ParameterError
        Unknown preset, or its file cannot be found.
    """
    if name not in PRESETS:
        raise ParameterError(f'unknown parameter set {name!r} (presets: {", ".join(PRESETS)})')
    for directory in _config_dirs():
        candidate = directory / f'{name}.yaml'
        if candidate.is_file():
            return candidate
    raise ParameterError(f'parameter set {name!r}: config file not found in the installation')


def load_parameters(spec: str | os.PathLike = 'maggy_v2') -> MaggyParameters:
    """Load a parameter set by preset name or YAML path.

    Parameters
    ----------
    spec : str or path
        ``maggy_v2``, ``maggy_v4`` or the path of a YAML file.

    Returns
    -------
    MaggyParameters

    Raises
    ------
    ParameterError
        File missing or unreadable, bad YAML, or invalid content (names file and key).
    """
    text = os.fspath(spec)
    path = preset_path(text) if text in PRESETS else Path(text)
    try:
        with open(path, encoding='utf-8') as stream:
            data = yaml.safe_load(stream)
    except FileNotFoundError:
        raise ParameterError(
            f'{path}: parameter file not found (presets: {", ".join(PRESETS)})'
        ) from None
    except yaml.YAMLError as err:
        raise ParameterError(f'{path}: invalid YAML, {yaml_error_text(err)}') from None
    except OSError as err:
        raise ParameterError(f'{path}: cannot read parameter file: {err}') from None
    return parameters_from_mapping(data, str(path))
