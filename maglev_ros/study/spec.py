"""A study file: what is fixed, what is varied on a grid, what is drawn at random.

A study is a YAML mapping::

    name: roa-v2            # optional, for titles
    duration: 1.0           # s of simulated time per run
    seed: 0                 # base seed; run i draws from SeedSequence([seed, i])
    repeats: 1              # runs per grid point (Monte Carlo draws)
    success:                # optional; these are the defaults
      bound: 3.0e-3         # m: |x|, |y|, |z - z_eq| never exceed it
      window: 0.3           # s: the RMS is taken over the run's last window (at most duration)
      rms: 1.0e-4           # m: largest RMS per axis over that window
    fixed:                  # one value each
      params: maggy_v2
    grid:                   # every combination (a list, or start/stop/num)
      controller: [lqr, pd]
      x0.x: {start: -2.0e-3, stop: 2.0e-3, num: 21}
    random:                 # one draw per run
      plant.polarization: {normal: {mean: 0.0, std: 0.05}}
      sensor.noise: {uniform: {low: 0.5e-4, high: 2.0e-4}}

Keys are the study parameters (:data:`~maglev_ros.study.parameters.PARAMETERS`).
Every problem raises :class:`~maglev_ros.study.parameters.StudyError` with a
message that names the file and the key.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..yaml_errors import yaml_error_text
from .parameters import StudyError, check_value, parameter

__all__ = [
    'Distribution',
    'StudySpec',
    'SuccessCriterion',
    'load_study',
    'study_from_mapping',
]

_TOP = ('name', 'duration', 'seed', 'repeats', 'success', 'fixed', 'grid', 'random')
_DISTRIBUTIONS = {'normal': ('mean', 'std'), 'uniform': ('low', 'high')}
MAX_RUNS = 10_000_000


@dataclass(frozen=True)
class SuccessCriterion:
    """When a run counts as a success.

    Attributes
    ----------
    bound : float
        m: no crash, and |x|, |y|, |z - z_eq| stay at most this over the whole run.
    window : float
        s: the settled RMS is taken over the run's last ``window`` (default 0.3 s,
        or the whole run when shorter).
    rms : float
        m: the largest RMS of x, y and z - z_eq over that window.
    """

    bound: float = 3.0e-3
    window: float = 0.3
    rms: float = 1.0e-4


@dataclass(frozen=True)
class Distribution:
    """A random parameter: ``normal`` (mean, std) or ``uniform`` (low, high).

    Attributes
    ----------
    kind : {'normal', 'uniform'}
    a, b : float
        mean and std, or low and high.
    """

    kind: str
    a: float
    b: float

    def draw(self, rng: np.random.Generator) -> float:
        """Draw one value.

        Parameters
        ----------
        rng : numpy.random.Generator
        """
        if self.kind == 'normal':
            return float(rng.normal(self.a, self.b))
        return float(rng.uniform(self.a, self.b))


@dataclass(frozen=True)
class StudySpec:
    """A validated study.

    Attributes
    ----------
    name : str
    duration : float
        s per run.
    seed : int
        Base seed.
    repeats : int
        Runs per grid point.
    success : SuccessCriterion
    fixed : dict
        Key to value.
    grid : dict
        Key to tuple of values (in file order).
    random : dict
        Key to :class:`Distribution`.
    source : str
        File, for messages.
    """

    name: str
    duration: float
    seed: int
    repeats: int
    success: SuccessCriterion
    fixed: dict = field(default_factory=dict)
    grid: dict = field(default_factory=dict)
    random: dict = field(default_factory=dict)
    source: str = '<memory>'

    @property
    def keys(self) -> list[str]:
        """The parameters the study sets, in column order (fixed, grid, random)."""
        return [*self.fixed, *self.grid, *self.random]

    @property
    def n_runs(self) -> int:
        """Number of runs."""
        return math.prod(len(v) for v in self.grid.values()) * self.repeats

    def to_mapping(self) -> dict:
        """Return the study as a plain mapping (what :func:`study_from_mapping` reads)."""
        return {
            'name': self.name,
            'duration': self.duration,
            'seed': self.seed,
            'repeats': self.repeats,
            'success': {
                'bound': self.success.bound,
                'window': self.success.window,
                'rms': self.success.rms,
            },
            'fixed': dict(self.fixed),
            'grid': {k: list(v) for k, v in self.grid.items()},
            'random': {
                k: {d.kind: dict(zip(_DISTRIBUTIONS[d.kind], (d.a, d.b), strict=True))}
                for k, d in self.random.items()
            },
        }

    def fingerprint(self) -> str:
        """Return a hash of everything that decides the runs (not the name)."""
        data = self.to_mapping()
        data.pop('name')
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def _number(value: Any, key: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise StudyError(f'{key}: expected a finite number, got {value!r}')
    if positive and value <= 0:
        raise StudyError(f'{key}: must be positive, got {value!r}')
    return float(value)


def _integer(value: Any, key: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise StudyError(f'{key}: expected an integer >= {low}, got {value!r}')
    return value


def _mapping(value: Any, key: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise StudyError(f'{key}: expected a mapping, got {value!r}')
    return dict(value)


def _grid_values(value: Any, key: str) -> tuple:
    if isinstance(value, Mapping):
        extra = set(value) - {'start', 'stop', 'num'}
        if extra or len(value) != 3:
            raise StudyError(
                f'{key}: a range needs exactly start, stop and num, got {dict(value)}'
            )
        start = _number(value['start'], f'{key}.start')
        stop = _number(value['stop'], f'{key}.stop')
        num = value['num']
        if isinstance(num, bool) or not isinstance(num, int) or num < 1:
            raise StudyError(f'{key}.num: empty grid: give at least 1 value, got {num!r}')
        values = [float(v) for v in np.linspace(start, stop, num)]
    elif isinstance(value, (list, tuple)):
        values = list(value)
    else:
        values = [value]
    if not values:
        raise StudyError(f'{key}: empty grid: give at least one value')
    name = key.split('.', 1)[1]
    checked = tuple(_checked(name, v, key) for v in values)
    if len(set(checked)) != len(checked):
        raise StudyError(f'{key}: repeated values {list(checked)}: use repeats for more runs')
    return checked


def _checked(name: str, value: Any, key: str) -> Any:
    try:
        return check_value(name, value)
    except StudyError as exc:
        raise StudyError(f'{key}{str(exc)[len(name) :]}') from None


def _distribution(value: Any, key: str) -> Distribution:
    name = key.split('.', 1)[1]
    if not parameter(name).numeric:
        raise StudyError(f'{key}: not a number: give its values under grid instead')
    if (
        not isinstance(value, Mapping)
        or len(value) != 1
        or next(iter(value)) not in _DISTRIBUTIONS
    ):
        raise StudyError(
            f'{key}: expected {{normal: {{mean, std}}}} or {{uniform: {{low, high}}}}, '
            f'got {value!r}'
        )
    kind, args = next(iter(value.items()))
    names = _DISTRIBUTIONS[kind]
    if not isinstance(args, Mapping) or set(args) != set(names):
        raise StudyError(f'{key}.{kind}: expected exactly {" and ".join(names)}, got {args!r}')
    a = _number(args[names[0]], f'{key}.{kind}.{names[0]}')
    b = _number(args[names[1]], f'{key}.{kind}.{names[1]}')
    if kind == 'normal' and b < 0:
        raise StudyError(f'{key}.normal.std: must be >= 0, got {b!r}')
    if kind == 'uniform' and not b > a:
        raise StudyError(f'{key}.uniform: high must exceed low, got {a!r} and {b!r}')
    return Distribution(kind, a, b)


def study_from_mapping(data: Any, source: str = '<memory>') -> StudySpec:
    """Validate a parsed study document.

    Parameters
    ----------
    data : mapping
        The YAML document (schema in the module docstring).
    source : str
        Name for messages (the file).

    Returns
    -------
    StudySpec

    Raises
    ------
    StudyError
        Unknown or malformed key, a bad value, an empty grid; the message
        names the file and the key.
    """
    try:
        return _from_mapping(data, source)
    except StudyError as exc:
        raise StudyError(f'{source}: {exc}') from None


def _from_mapping(data: Any, source: str) -> StudySpec:
    if not isinstance(data, Mapping):
        raise StudyError(f'expected a mapping with keys {", ".join(_TOP)}, got {data!r}')
    for key in data:
        if key not in _TOP:
            raise StudyError(f'{key}: unknown key (allowed: {", ".join(_TOP)})')
    name = data.get('name', Path(source).stem if source != '<memory>' else 'study')
    if not isinstance(name, str) or not name:
        raise StudyError(f'name: expected a non-empty string, got {name!r}')
    if 'duration' not in data:
        raise StudyError('duration: missing (s of simulated time per run)')
    duration = _number(data['duration'], 'duration', positive=True)
    seed = _integer(data.get('seed', 0), 'seed', 0)
    repeats = _integer(data.get('repeats', 1), 'repeats', 1)
    raw = _mapping(data.get('success'), 'success')
    for key in raw:
        if key not in ('bound', 'window', 'rms'):
            raise StudyError(f'success.{key}: unknown key (allowed: bound, window, rms)')
    defaults = SuccessCriterion(window=min(SuccessCriterion.window, duration))
    success = SuccessCriterion(
        **{
            k: _number(raw.get(k, getattr(defaults, k)), f'success.{k}', positive=True)
            for k in ('bound', 'window', 'rms')
        }
    )
    if success.window > duration:
        raise StudyError(
            f'success.window: {success.window} s is longer than the duration {duration} s'
        )
    seen: dict[str, str] = {}
    sections = {}
    for section in ('fixed', 'grid', 'random'):
        entries = _mapping(data.get(section), section)
        for key in entries:
            if not isinstance(key, str):
                raise StudyError(f'{section}.{key}: expected a parameter name')
            try:
                parameter(key)
            except StudyError as exc:
                raise StudyError(f'{section}.{exc}') from None
            if key in seen:
                raise StudyError(f'{section}.{key}: already set under {seen[key]}')
            seen[key] = section
        sections[section] = entries
    fixed = {k: _checked(k, v, f'fixed.{k}') for k, v in sections['fixed'].items()}
    grid = {k: _grid_values(v, f'grid.{k}') for k, v in sections['grid'].items()}
    random = {k: _distribution(v, f'random.{k}') for k, v in sections['random'].items()}
    spec = StudySpec(name, duration, seed, repeats, success, fixed, grid, random, source)
    if spec.n_runs > MAX_RUNS:
        raise StudyError(f'grid: {spec.n_runs} runs is more than {MAX_RUNS}: coarsen the grid')
    return spec


def load_study(path: str | Path) -> StudySpec:
    """Read and validate a study file.

    Parameters
    ----------
    path : str or Path
        The YAML file.

    Raises
    ------
    StudyError
        Missing file, bad YAML or invalid content (names the file and the key).
    """
    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text(encoding='utf-8'))
    except FileNotFoundError:
        raise StudyError(f'{p}: study file not found') from None
    except yaml.YAMLError as exc:
        raise StudyError(f'{p}: invalid YAML, {yaml_error_text(exc)}') from None
    except OSError as exc:
        raise StudyError(f'{p}: cannot read the study file: {exc}') from None
    return study_from_mapping(data, str(p))
