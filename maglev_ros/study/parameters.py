"""The quantities a study may vary: names, units, defaults and the check of each value.

A study names what it varies with dotted keys: ``plant.polarization`` (the
simulated magnet's polarisation error), ``x0.x`` (the initial x offset),
``controller.position_scale`` (an LQR weight), ``estimator.filter``, ... Every
value is checked here, so a study file with a bad value fails before any run.
The controller's and the estimator's settings are taken from their
configuration classes, so a new setting is a study parameter at once.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..control.config import MAX_COMMAND_DELAY, MODES, ControllerConfig
from ..estimation.config import FILTERS, EstimatorConfig
from ..physics.parameters import PRESETS

__all__ = ['StudyError', 'StudyParameter', 'PARAMETERS', 'check_value', 'parameter']


class StudyError(ValueError):
    """A study file or value is invalid; the message names the key."""


@dataclass(frozen=True)
class StudyParameter:
    """One quantity a study may set or vary.

    Attributes
    ----------
    name : str
        Dotted key (``plant.polarization``).
    kind : {'number', 'integer', 'choice', 'flag', 'text'}
        Value type; numbers may come from a distribution, the rest only from lists.
    default : object
        The value when the study does not set it.
    unit : str
        Unit of a number (``'1'`` for a relative value).
    description : str
        One line for ``maglev-study --list``.
    check : callable
        ``check(value) -> str or None``: the problem with a value, if any.
    """

    name: str
    kind: str
    default: Any
    unit: str
    description: str
    check: Callable[[Any], str | None] = lambda value: None

    @property
    def numeric(self) -> bool:
        """Whether values may be drawn from a distribution."""
        return self.kind == 'number'


def _at_least(low: float, strict: bool = False) -> Callable[[Any], str | None]:
    def check(value: Any) -> str | None:
        if value < low or (strict and value == low):
            return f'must be {">" if strict else ">="} {low:g}, got {value!r}'
        return None

    return check


def _relative(value: Any) -> str | None:
    return None if value > -1.0 else f'must be above -1 (a relative error), got {value!r}'


def _params(value: Any) -> str | None:
    if value in PRESETS or os.path.isfile(str(value)):
        return None
    return f'expected {" or ".join(PRESETS)} or a parameter file, got {value!r}'


def _command_delay(value: Any) -> str | None:
    if 0 <= value <= MAX_COMMAND_DELAY:
        return None
    return f'must be from 0 to {MAX_COMMAND_DELAY} samples, got {value!r}'


def _one_of(choices: tuple) -> Callable[[Any], str | None]:
    def check(value: Any) -> str | None:
        return (
            None
            if value in choices
            else f'expected one of {", ".join(map(str, choices))}, got {value!r}'
        )

    return check


def _own() -> dict[str, StudyParameter]:
    p = [
        StudyParameter(
            'params', 'text', 'maggy_v2', '', 'parameter set (believed and simulated)', _params
        ),
        StudyParameter('controller', 'choice', 'lqr', '', 'lqr or pd', _one_of(MODES)),
        StudyParameter(
            'estimator', 'choice', 'kf', '', 'kf, ekf or ukf (LQR only)', _one_of(FILTERS)
        ),
        StudyParameter(
            'plant.polarization',
            'number',
            0.0,
            '1',
            "magnet's polarisation error, relative",
            _relative,
        ),
        StudyParameter(
            'plant.mass', 'number', 0.0, '1', "magnet's mass error, relative", _relative
        ),
        StudyParameter(
            'plant.coil_resistance',
            'number',
            0.0,
            '1',
            'coil resistance error, relative',
            _relative,
        ),
        StudyParameter('plant.sensor_dx', 'number', 0.0, 'm', 'every sensor moved by this in x'),
        StudyParameter('plant.sensor_dy', 'number', 0.0, 'm', 'every sensor moved by this in y'),
        StudyParameter('plant.sensor_dz', 'number', 0.0, 'm', 'every sensor moved by this in z'),
        StudyParameter(
            'plant.sensor_offset_x', 'number', 0.0, 'T', 'offset added to every Bx reading'
        ),
        StudyParameter(
            'plant.sensor_offset_y', 'number', 0.0, 'T', 'offset added to every By reading'
        ),
        StudyParameter(
            'plant.sensor_offset_z', 'number', 0.0, 'T', 'offset added to every Bz reading'
        ),
        StudyParameter(
            'sensor.noise', 'number', 1.0e-4, 'T', 'Hall noise, rms per axis', _at_least(0.0)
        ),
        StudyParameter(
            'sensor.quantization',
            'number',
            0.098e-3,
            'T',
            'Hall resolution per LSB',
            _at_least(0.0),
        ),
        StudyParameter(
            'sensor.delay',
            'integer',
            1,
            'samples',
            'reading delay (0 or 1; the filters and PD know it)',
            _one_of((0, 1)),
        ),
        StudyParameter(
            'loop.command_delay',
            'integer',
            -1,
            'samples',
            "samples before a command acts (-1: the controller's design value)",
            lambda v: None if v == -1 else _command_delay(v),
        ),
        StudyParameter('x0.x', 'number', 0.0, 'm', 'initial x offset from the equilibrium'),
        StudyParameter('x0.y', 'number', 0.0, 'm', 'initial y offset from the equilibrium'),
        StudyParameter('x0.z', 'number', 0.0, 'm', 'initial z offset from the equilibrium'),
        StudyParameter('x0.alpha', 'number', 0.0, 'rad', 'initial tilt about x'),
        StudyParameter('x0.beta', 'number', 0.0, 'rad', 'initial tilt about y'),
    ]
    return {q.name: q for q in p}


def _from_config(prefix: str, cls: type, skip: tuple[str, ...]) -> dict[str, StudyParameter]:
    out = {}
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        default = f.default
        kind = {bool: 'flag', int: 'integer', float: 'number', str: 'text'}[type(default)]
        name = f'{prefix}.{f.name}'
        out[name] = StudyParameter(
            name, kind, default, 'SI', f'{cls.__name__}.{f.name}', _config_check(cls, f.name)
        )
    return out


def _config_check(cls: type, field: str) -> Callable[[Any], str | None]:
    def check(value: Any) -> str | None:
        try:
            cls(**{field: value})
        except ValueError as exc:
            return str(exc)
        return None

    return check


#: Every study parameter by key.
PARAMETERS: dict[str, StudyParameter] = {
    **_own(),
    **_from_config('controller', ControllerConfig, ('mode', 'sensor_delay')),
    **_from_config('estimator', EstimatorConfig, ('filter', 'sample_rate', 'sensor_delay')),
}


def parameter(key: str) -> StudyParameter:
    """Return the study parameter ``key``.

    Parameters
    ----------
    key : str
        Dotted key.

    Raises
    ------
    StudyError
        Unknown key (the message names it and points to ``--list``).
    """
    try:
        return PARAMETERS[key]
    except KeyError:
        close = difflib.get_close_matches(str(key), PARAMETERS, n=1)
        hint = f'did you mean {close[0]}? ' if close else ''
        raise StudyError(
            f'{key}: unknown parameter ({hint}maglev-study --list shows the known ones)'
        ) from None


def check_value(key: str, value: Any) -> Any:
    """Return ``value`` converted to the parameter's type, or raise naming the key.

    Parameters
    ----------
    key : str
        Dotted key.
    value : object
        A value from the study file (YAML scalar).

    Raises
    ------
    StudyError
        Wrong type, out of range, or unknown key.
    """
    p = parameter(key)
    if p.kind in ('number', 'integer'):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise StudyError(f'{key}: expected a number, got {value!r}')
        if p.kind == 'integer':
            if float(value) != int(value):
                raise StudyError(f'{key}: expected an integer, got {value!r}')
            value = int(value)
        else:
            value = float(value)
            if not math.isfinite(value):
                raise StudyError(f'{key}: must be finite, got {value!r}')
    elif p.kind == 'flag':
        if not isinstance(value, bool):
            raise StudyError(f'{key}: expected true or false, got {value!r}')
    elif not isinstance(value, str):
        raise StudyError(f'{key}: expected a name, got {value!r}')
    problem = p.check(value)
    if problem:
        raise StudyError(f'{key}: {problem}')
    return value
