"""Parameters from one source: config fields, node tables, rules and ``--help``.

A core config (a frozen dataclass such as
:class:`~maglev_ros.control.ControllerConfig`) declares each field once with
:func:`setting`: default, one-line description with its unit, and value rule.
From it come the config's own check (:func:`check_settings`, in its
``__post_init__``) and the node's parameters (:meth:`ParameterTable.from_config`),
so a rule is written once. A node writes its other parameters as a
:class:`Param` in its :class:`ParameterTable`; from that table come

* the declaration (``declare`` of :class:`maglev_ros.nodes.params.ParameterTable`,
  the table's ROS side): typed default, ``ParameterDescriptor`` with
  description, read-only flag and range;
* the type rules (:meth:`ParameterTable.validate`), the same at start-up and at
  run time: an integer is accepted where a double is expected (``-p
  sample_rate:=5000``), any other type is refused in one line naming the
  parameter;
* the per-parameter value rules (the ``check`` of each :class:`Param`:
  :func:`choice`, :func:`number`, :func:`integer` or the node's own);
* the on-set callback of the mutable parameters (its ``on_set``),
  which rebuilds the node's frozen config with the same ``build_config`` as
  start-up;
* the ``--help`` text (:meth:`ParameterTable.help_text`, :func:`help_requested`).

Every parameter is declared with a value, so ``ros2 param dump`` lists all of
them: a parameter whose default means "unset" (an initial state, a sensor
list) has an empty list. Parameters are declared with dynamic typing and the
table enforces its own type, because rclpy refuses an integer override of a
double-typed parameter before any node code runs.

This module imports no ROS: the configs of the core use it, and the table, the
checks and the help are unit-testable without ROS.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, NamedTuple

__all__ = [
    'KINDS',
    'PARAMS',
    'NodeParameterError',
    'Param',
    'ParameterTable',
    'check_settings',
    'config_params',
    'choice',
    'coerce',
    'help_requested',
    'integer',
    'node_name',
    'number',
    'setting',
    'topic_names',
]


class NodeParameterError(ValueError):
    """A node parameter has an invalid value or type (the message names both)."""


#: Parameter kinds and their ``rcl_interfaces/ParameterType`` names.
KINDS = {
    'bool': 'PARAMETER_BOOL',
    'integer': 'PARAMETER_INTEGER',
    'double': 'PARAMETER_DOUBLE',
    'string': 'PARAMETER_STRING',
    'bool_array': 'PARAMETER_BOOL_ARRAY',
    'integer_array': 'PARAMETER_INTEGER_ARRAY',
    'double_array': 'PARAMETER_DOUBLE_ARRAY',
    'string_array': 'PARAMETER_STRING_ARRAY',
}
_SCALAR_KIND = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
_TYPE_WORDS = {
    'bool': 'true or false',
    'integer': 'an integer',
    'double': 'a number',
    'string': 'a string',
    'bool_array': 'a list of true/false values',
    'integer_array': 'a list of integers',
    'double_array': 'a list of numbers',
    'string_array': 'a list of strings',
}

Check = Callable[[str, Any], Any]


class Param(NamedTuple):
    """One node parameter.

    Attributes
    ----------
    default : object
        Default value; its Python type fixes the kind (a list for arrays).
    description : str
        One line for ``ros2 param describe`` and ``--help`` (units included).
    kind : str, optional
        One of :data:`KINDS`; needed only for an empty-list default.
    check : callable, optional
        ``check(name, value) -> value``: the value rule after the type rule
        (raises :class:`NodeParameterError`); returns the value to keep.
    mutable : bool
        Whether it may change at run time (else read-only).
    """

    default: Any
    description: str
    kind: str | None = None
    check: Check | None = None
    mutable: bool = False

    @property
    def type_kind(self) -> str:
        """The parameter's kind (:data:`KINDS` key)."""
        if self.kind is not None:
            return self.kind
        default = self.default
        if isinstance(default, (list, tuple)):
            if not default:
                raise ValueError('an empty-list default needs an explicit kind')
            return _SCALAR_KIND[type(default[0])] + '_array'
        return _SCALAR_KIND[type(default)]

    @property
    def constraints(self) -> str:
        """The type and value rule in words (``ros2 param describe``, ``--help``)."""
        rule = getattr(self.check, 'rule', '')
        return f'{self.type_kind}{", " + rule if rule else ""}'


def _type_error(name: str, kind: str, value: object) -> NodeParameterError:
    return NodeParameterError(f'{name} must be {_TYPE_WORDS[kind]}, got {value!r}')


def _scalar(name: str, kind: str, value: object) -> object:
    if kind == 'double':
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _type_error(name, 'double', value)
        return float(value)
    if kind == 'integer':
        if isinstance(value, bool) or not isinstance(value, int):
            raise _type_error(name, 'integer', value)
        return value
    if kind == 'bool':
        if not isinstance(value, bool):
            raise _type_error(name, 'bool', value)
        return value
    if not isinstance(value, str):
        raise _type_error(name, 'string', value)
    return value


def coerce(name: str, kind: str, value: object) -> object:
    """Apply the type rule of ``kind`` to ``value``.

    Parameters
    ----------
    name : str
        Parameter name (for the message).
    kind : str
        One of :data:`KINDS`.
    value : object
        The value as rclpy holds it (arrays as list or array.array; None or
        an empty array of any type for an empty array).

    Returns
    -------
    object
        ``float`` for a double (an integer accepted), tuple for an array.

    Raises
    ------
    NodeParameterError
        If the value is not of the kind.
    """
    if kind.endswith('_array'):
        if value is None:
            return ()
        if isinstance(value, (str, bytes)) or not hasattr(value, '__iter__'):
            raise _type_error(name, kind, value)
        items = list(value)
        try:
            return tuple(_scalar(name, kind[:-6], v) for v in items)
        except NodeParameterError:
            raise _type_error(name, kind, items) from None
    return _scalar(name, kind, value)


# --------------------------------------------------------------------------- value rules
def choice(*allowed: str) -> Check:
    """Check: the value is one of ``allowed`` ("must be one of a, b, got 'c'").

    Parameters
    ----------
    *allowed : str
        The accepted values.

    Returns
    -------
    callable
    """

    def check(name: str, value: str) -> str:
        if value not in allowed:
            raise NodeParameterError(f'{name} must be one of {", ".join(allowed)}, got {value!r}')
        return value

    check.rule = f'one of {", ".join(allowed)}'
    return check


def number(low: float | None = None, *, above: bool = False, high: float | None = None) -> Check:
    """Check: a finite number ``>= low`` (``> low`` if ``above``) and ``<= high``.

    Parameters
    ----------
    low : float, optional
        Lower bound (none if None).
    above : bool
        Exclude ``low`` itself.
    high : float, optional
        Upper bound, included (none if None).

    Returns
    -------
    callable
    """
    bounds = []
    if low is not None:
        bounds.append(f'{">" if above else ">="} {low:g}')
    if high is not None:
        bounds.append(f'<= {high:g}')
    text = ''.join(' ' + b for b in bounds[:1]) + ''.join(' and ' + b for b in bounds[1:])

    def check(name: str, value: float) -> float:
        ok = math.isfinite(value)
        if ok and low is not None:
            ok = value > low if above else value >= low
        if ok and high is not None:
            ok = value <= high
        if not ok:
            raise NodeParameterError(f'{name} must be a finite number{text}, got {value!r}')
        return value

    check.rule = text.strip()
    return check


def integer(low: int, high: int | None = None) -> Check:
    """Check: an integer ``>= low`` (and ``<= high``).

    Parameters
    ----------
    low : int
        Lower bound, included.
    high : int, optional
        Upper bound, included.

    Returns
    -------
    callable
    """

    def check(name: str, value: int) -> int:
        if value < low or (high is not None and value > high):
            if high is None:
                raise NodeParameterError(f'{name} must be an integer >= {low}, got {value!r}')
            raise NodeParameterError(f'{name} must be in {low} .. {high}, got {value!r}')
        return value

    check.rule = f'>= {low}' if high is None else f'{low} .. {high}'
    return check


_NAME = r'[A-Za-z_][A-Za-z0-9_]*'


def node_name() -> Check:
    """Check: a node name without namespace (what ``Node.get_name()`` gives), or ''.

    Returns
    -------
    callable
    """

    def check(name: str, value: str) -> str:
        if value and not re.fullmatch(_NAME, value):
            raise NodeParameterError(
                f'{name} must be a node name (letters, digits, _) or empty, got {value!r}'
            )
        return value

    check.rule = "a node name or ''"
    return check


def topic_names() -> Check:
    """Check: one or more topic names (``a/b``, or ``/a/b``), duplicates dropped.

    Returns
    -------
    callable
    """

    def check(name: str, values: tuple[str, ...]) -> tuple[str, ...]:
        if not values or not all(re.fullmatch(f'/?{_NAME}(/{_NAME})*', v) for v in values):
            raise NodeParameterError(f'{name} must name topics, got {list(values)}')
        return tuple(dict.fromkeys(values))

    check.rule = 'topic names'
    return check


# --------------------------------------------------------------------------- the table
class ParameterTable(Mapping[str, Param]):
    """A node's parameters, in declaration order.

    Parameters
    ----------
    node_name : str
        The node's default name (for ``--help``).
    error : type
        The node's error class (a :class:`NodeParameterError` subclass); rule
        failures are raised as it.
    params : mapping
        ``name -> Param``.
    removed : mapping, optional
        ``name -> what replaced it``: parameters the node no longer has. A
        value given for one is refused (:meth:`validate`, :meth:`declare`) in
        one line that says what replaced it, never silently ignored.
    """

    def __init__(
        self,
        node_name: str,
        error: type[NodeParameterError],
        params: Mapping[str, Param],
        removed: Mapping[str, str] | None = None,
    ) -> None:
        if not issubclass(error, NodeParameterError):
            raise TypeError(f'{error.__name__} must subclass NodeParameterError')
        self.node_name = node_name
        self.error = error
        self._params = dict(params)
        self.removed = dict(removed or {})
        for name, param in self._params.items():
            kind = param.type_kind
            if kind not in KINDS:
                raise ValueError(f'{name}: unknown parameter kind {kind!r}')

    def __getitem__(self, name: str) -> Param:
        return self._params[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._params)

    def __len__(self) -> int:
        return len(self._params)

    @property
    def mutable(self) -> tuple[str, ...]:
        """Names of the parameters that may change at run time."""
        return tuple(name for name, p in self._params.items() if p.mutable)

    # -- rules -------------------------------------------------------------------
    def check_value(self, name: str, value: object) -> object:
        """Apply the type rule and the value rule of parameter ``name``.

        Parameters
        ----------
        name : str
            A parameter of the table.
        value : object
            Raw value.

        Returns
        -------
        object
            The value to keep (doubles as float, arrays as tuples).

        Raises
        ------
        NodeParameterError
            As the table's error class.
        """
        param = self._params[name]
        try:
            value = coerce(name, param.type_kind, value)
            return value if param.check is None else param.check(name, value)
        except NodeParameterError as err:
            if isinstance(err, self.error):
                raise
            raise self.error(str(err)) from None

    def validate(self, values: Mapping[str, object]) -> dict[str, object]:
        """Apply every parameter's rules to ``values`` (a missing one takes its default).

        Parameters
        ----------
        values : mapping
            ``name -> raw value``.

        Returns
        -------
        dict
            ``name -> value`` in table order.

        Raises
        ------
        NodeParameterError
            As the table's error class, naming the first invalid parameter
            (or a removed one that was given).
        """
        for name in values:
            if name in self.removed:
                self.refuse_removed(name)
        return {
            name: self.check_value(name, values.get(name, param.default))
            for name, param in self._params.items()
        }

    def refuse_removed(self, name: str) -> None:
        """Raise the table's error for the removed parameter ``name``.

        Parameters
        ----------
        name : str
            A key of :attr:`removed`.

        Raises
        ------
        NodeParameterError
            As the table's error class: ``NAME was removed: REPLACEMENT``.
        """
        raise self.error(f'{name} was removed: {self.removed[name]}')

    # -- help ------------------------------------------------------------------------
    def help_text(self, prog: str | None = None) -> str:
        """Return the node's ``--help``: how to set parameters, then one line each.

        Parameters
        ----------
        prog : str, optional
            Executable name (default the node name).

        Returns
        -------
        str
        """
        prog = prog or self.node_name
        lines = [
            f'usage: ros2 run maglev_ros {prog} [--ros-args -p NAME:=VALUE ...]',
            '',
            f'ROS 2 node {self.node_name}. Parameters (read-only unless marked '
            '"settable at run time"):',
        ]
        width = max(len(name) for name in self._params)
        for name, param in self._params.items():
            default = param.default
            shown = repr(list(default)) if isinstance(default, (list, tuple)) else repr(default)
            if isinstance(default, bool):
                shown = str(default).lower()
            extra = ', settable at run time' if param.mutable else ''
            lines.append(
                f'  {name:<{width}}  {param.constraints}, default {shown}{extra}: '
                f'{param.description}'
            )
        return '\n'.join(lines) + '\n'


def _parameter_set(name: str, value: str) -> str:
    if not value:
        raise NodeParameterError(f'{name} must name a parameter set, got an empty string')
    return value


#: The ``params`` parameter of every node that loads a parameter set.
PARAMS = Param(
    'maggy_v2', 'parameter set: maggy_v2, maggy_v4 or a YAML path', check=_parameter_set
)


def setting(default: Any, description: str, check: Check | None = None, **kw) -> Any:
    """Declare a config field with its description and rule (a ``dataclasses.field``).

    Parameters
    ----------
    default : object
        Default value; its Python type fixes the parameter's kind.
    description : str
        One line, with the unit (the node's parameter description, ``--help``,
        the docs' tables).
    check : callable, optional
        ``check(name, value) -> value``, raising :class:`NodeParameterError`.
    **kw
        More :class:`Param` fields (``kind``, ``mutable``).

    Returns
    -------
    dataclasses.Field
    """
    param = Param(default, description, check=check, **kw)
    return dataclasses.field(default=default, metadata={'param': param})


def config_params(config: type, prefix: str = '') -> dict[str, Param]:
    """Return the :class:`Param` of every :func:`setting` field of ``config``.

    Parameters
    ----------
    config : dataclass type
        A config whose fields were declared with :func:`setting`.
    prefix : str
        Prepended to each field's name (``excitation_`` for ``amplitude``).
    """
    return {
        prefix + f.name: f.metadata['param']
        for f in dataclasses.fields(config)
        if 'param' in f.metadata
    }


def check_settings(config: Any, error: type[Exception]) -> None:
    """Apply the type and value rules of every :func:`setting` field of ``config``.

    Meant for a frozen config's ``__post_init__``: a value the rule changes
    (an integer for a float, a list for a tuple) is stored as the rule returns it.

    Parameters
    ----------
    config : dataclass instance
        The config to check.
    error : exception type
        Raised with the rule's message (``from`` the rule's error).
    """
    for name, param in config_params(type(config)).items():
        value = getattr(config, name)
        try:
            try:
                kept = coerce(name, param.type_kind, value)
            except NodeParameterError:
                if param.check is not None:  # its own words, where it has them
                    try:
                        param.check(name, value)
                    except (TypeError, ValueError) as other:
                        if isinstance(other, NodeParameterError):
                            raise
                raise
            if param.check is not None:
                kept = param.check(name, kept)
        except NodeParameterError as err:
            raise error(str(err)) from err
        if kept is not value:
            object.__setattr__(config, name, kept)


def help_requested(args: Sequence[str] | None) -> bool:
    """Whether the command line asks for ``--help`` (``-h``) before any ``--ros-args``.

    Parameters
    ----------
    args : sequence of str or None
        The full command line (``sys.argv``), or None for ``sys.argv``.

    Returns
    -------
    bool
    """
    import sys

    argv = list(sys.argv if args is None else args)
    if '--ros-args' in argv:
        argv = argv[: argv.index('--ros-args')]
    if argv and not argv[0].startswith('-'):
        argv = argv[1:]  # the program
    return any(a in ('-h', '--help') for a in argv)
