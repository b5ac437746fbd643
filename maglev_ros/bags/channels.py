r"""Channel specs: which number of which message becomes a data-set channel.

Syntax (whitespace is ignored)::

    channel  := [NAME '='] term (('+' | '-') term)*
    term     := ['-'] [NUMBER '*'] TOPIC ':' PATH
    PATH     := FIELD ('.' FIELD | '[' INDEX ']')*

``TOPIC`` is a ROS topic name with or without the leading ``/``; ``PATH`` walks
message fields (``magnetic_field.x``) and array elements (``effort[0]``,
counted from 0).  Examples::

    maglev/sensor_0/field:magnetic_field.x
    /maglev/currents:effort[0]
    ux=0.5*maglev/currents:effort[0]-0.5*maglev/currents:effort[1]

A channel is a linear combination of field values (the antisymmetric pair
input above); its name is ``NAME`` if given, else the spec text.  Parsing is a
small tokenizer and recursive scan, never ``eval``.  :func:`check_field`
validates a path against the message definition and names the fields that
exist where it fails.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

from ..topics import CHANNEL_UNITS, COMMAND_TOPIC, EXCITATION_TOPIC, current_channel
from .errors import BagError
from .names import normalize_topic

__all__ = [
    'COMMAND_TOPICS',
    'Channel',
    'FieldRef',
    'check_field',
    'command_alias',
    'parse_channel',
    'parse_field_path',
    'unit_of',
]

_NUMBER = r'(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?'
_TOPIC = r'/?[A-Za-z_~][A-Za-z0-9_/]*'
_PATH = r'[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*|\[\d+\])*'
_TERM = re.compile(
    rf'\s*(?P<sign>[+-])?\s*(?:(?P<coef>{_NUMBER})\s*\*\s*)?'
    rf'(?P<topic>{_TOPIC})\s*:\s*(?P<path>{_PATH})\s*'
)
_PATH_PART = re.compile(r'\.?([A-Za-z_][A-Za-z0-9_]*)|\[(\d+)\]')
_NUMERIC = {
    'bool',
    'byte',
    'char',
    'octet',
    'int8',
    'uint8',
    'int16',
    'uint16',
    'int32',
    'uint32',
    'int64',
    'uint64',
    'float32',
    'float64',
}


def parse_field_path(text: str) -> tuple[str | int, ...]:
    """Parse a field path such as ``magnetic_field.x`` or ``effort[0]``.

    Parameters
    ----------
    text : str
        Dotted field names and ``[i]`` indices (from 0).

    Returns
    -------
    tuple of str and int
        Field names (str) and indices (int) in order.
    """
    text = text.strip()
    if not re.fullmatch(_PATH, text):
        raise BagError(
            f'invalid field path {text!r}: expected fields and indices like '
            f'magnetic_field.x or effort[0]'
        )
    return tuple(name if name else int(index) for name, index in _PATH_PART.findall(text))


def format_field_path(path: tuple[str | int, ...]) -> str:
    """Return the text of a parsed field path (inverse of :func:`parse_field_path`).

    Parameters
    ----------
    path : tuple of str or int
        Field names and array indices, as :func:`parse_field_path` returns them.
    """
    out = ''
    for part in path:
        out += f'[{part}]' if isinstance(part, int) else (f'.{part}' if out else part)
    return out


@dataclass(frozen=True)
class FieldRef:
    """One numeric field of the messages of one topic.

    Parameters
    ----------
    topic : str
        Absolute topic name.
    path : tuple of str and int
        Field names and array indices, see :func:`parse_field_path`.
    """

    topic: str
    path: tuple[str | int, ...]

    @property
    def text(self) -> str:
        """The reference as ``TOPIC:PATH``."""
        return f'{self.topic}:{format_field_path(self.path)}'


@dataclass(frozen=True)
class Channel:
    """A data-set channel: a linear combination of message fields.

    Parameters
    ----------
    name : str
        Channel name.
    terms : tuple of (float, FieldRef)
        Coefficients and fields; the channel is ``sum(c * field)``.
    spec : str
        The spec text it was parsed from.
    """

    name: str
    terms: tuple[tuple[float, FieldRef], ...]
    spec: str

    @property
    def expression(self) -> str:
        """The spec without its ``NAME=`` prefix."""
        return self.spec.split('=', 1)[1].strip() if '=' in self.spec else self.spec

    @property
    def topics(self) -> tuple[str, ...]:
        """Topics the channel reads, in order of first use."""
        return tuple(dict.fromkeys(ref.topic for _, ref in self.terms))


def parse_channel(spec: str) -> Channel:
    """Parse a channel spec ``[NAME=]TERM (+|- TERM)*`` (see the module docstring).

    Parameters
    ----------
    spec : str
        The spec, e.g. ``'maglev/currents:effort[0]'``.

    Returns
    -------
    Channel
        The parsed channel.
    """
    text = str(spec).strip()
    name = None
    if '=' in text:
        name, text = (s.strip() for s in text.split('=', 1))
        if not name or any(c in name for c in ',\n"'):
            raise BagError(f'invalid channel name {name!r} in {spec!r} (no commas or quotes)')
    terms: list[tuple[float, FieldRef]] = []
    pos = 0
    while pos < len(text):
        match = _TERM.match(text, pos)
        if match is None or (terms and not match.group('sign')):
            where = text[pos : pos + 20]
            raise BagError(
                f'invalid channel spec {spec!r} at {where!r}: expected '
                f'[COEF*]TOPIC:FIELD terms joined by + or -, e.g. '
                f'0.5*{current_channel(0)}-0.5*{current_channel(1)}'
            )
        coef = float(match.group('coef')) if match.group('coef') else 1.0
        if match.group('sign') == '-':
            coef = -coef
        path = parse_field_path(match.group('path'))
        terms.append((coef, FieldRef(normalize_topic(match.group('topic')), path)))
        pos = match.end()
    if not terms:
        raise BagError(f'empty channel spec {spec!r}: expected TOPIC:FIELD')
    return Channel(name or text.replace(' ', ''), tuple(terms), str(spec).strip())


#: Topics of coil commands, whose currents are ``data[i]`` (Float64MultiArray) or
#: ``effort[i]`` (JointState): see :mod:`~maglev_ros.bags.command_fields`.
COMMAND_TOPICS = frozenset(normalize_topic(t) for t in (COMMAND_TOPIC, EXCITATION_TOPIC))


def command_alias(ref: FieldRef) -> FieldRef | None:
    """Return the other spelling of a command current (``data[i]`` <-> ``effort[i]``).

    Parameters
    ----------
    ref : FieldRef
        A field reference.

    Returns
    -------
    FieldRef or None
        The reference in the other message type, or None if ``ref`` is not
        ``data[i]`` / ``effort[i]`` of a command topic.
    """
    path = ref.path
    if ref.topic not in COMMAND_TOPICS or len(path) != 2 or not isinstance(path[1], int):
        return None
    other = {'data': 'effort', 'effort': 'data'}.get(path[0])
    return None if other is None else FieldRef(ref.topic, (other, path[1]))


def _fields(typestore: Typestore, msgtype: str) -> list[tuple[str, tuple]]:
    return list(typestore.fielddefs[msgtype][1])


def check_field(typestore: Typestore, msgtype: str, ref: FieldRef) -> None:
    """Check that a field path leads to one number in messages of ``msgtype``.

    Parameters
    ----------
    typestore : rosbags Typestore
        Store that knows ``msgtype``.
    msgtype : str
        The topic's message type.
    ref : FieldRef
        The field reference.

    Raises
    ------
    BagError
        Unknown field (the message lists the fields there), an index into a
        non-array, an index beyond a fixed array, or a path that ends at a
        message, array or string.
    """
    current: tuple = (Nodetype.NAME, msgtype)
    walked = ''
    for part in ref.path:
        kind, detail = current
        if isinstance(part, str):
            if kind != Nodetype.NAME:
                raise BagError(f'{ref.text}: {walked} is not a message, it has no field {part!r}')
            fields = dict(_fields(typestore, detail))
            if part not in fields:
                where = f'{walked} ({detail})' if walked else detail
                raise BagError(
                    f'{ref.text}: {where} has no field {part!r}; its fields: {", ".join(fields)}'
                )
            current = fields[part]
        else:
            if kind not in (Nodetype.ARRAY, Nodetype.SEQUENCE):
                raise BagError(f'{ref.text}: {walked} is not an array, it cannot be indexed')
            sub, size = detail
            if kind == Nodetype.ARRAY and part >= size:
                raise BagError(
                    f'{ref.text}: index {part} out of range, {walked} has {size} elements'
                )
            current = sub
        walked += f'[{part}]' if isinstance(part, int) else (f'.{part}' if walked else part)
    kind, detail = current
    if kind == Nodetype.NAME:
        fields = ', '.join(name for name, _ in _fields(typestore, detail))
        raise BagError(
            f'{ref.text} is a {detail} message, not a number; choose one of its fields: {fields}'
        )
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        raise BagError(f'{ref.text} is an array; choose an element, e.g. {ref.text}[0]')
    if detail[0] not in _NUMERIC:
        raise BagError(f'{ref.text} is a {detail[0]}, not a number')


def unit_of(channel: Channel) -> str:
    """Return the unit of a channel by the topic contract, '' if unknown or mixed.

    Parameters
    ----------
    channel : Channel
        The channel.

    Returns
    -------
    str
        SI unit (``'T'``, ``'A'``, ``'m'`` ...) shared by all terms, else ``''``.
    """
    units = set()
    for _, ref in channel.terms:
        alias = command_alias(ref)  # a command's data[i] is its effort[i]
        paths = [format_field_path(r.path) for r in (ref, alias) if r is not None]
        unit = next(
            (
                u
                for path in paths
                for pattern, prefix, u in CHANNEL_UNITS
                if re.fullmatch(pattern, ref.topic) and path.startswith(prefix)
            ),
            '',
        )
        units.add(unit)
    return units.pop() if len(units) == 1 else ''
