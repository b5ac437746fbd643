"""Raw message templates: a message serialised once and where its varying fields sit.

The messages the simulator and the board driver publish at 5 kHz differ from
sample to sample only in their stamp and a few float64 fields. A template
message is serialised once (by rosbags, over ROS 2 Jazzy's definitions: no
rclpy) and the byte offsets of its stamp and varying fields are located by
the same CDR walker that decodes bags (:func:`maglev_ros.cdr.layout.cdr_layout`):
one piece of code knows where fields sit in CDR, for reading bags and for
publishing bytes. :mod:`maglev_ros.cdr.batch` then writes a burst of messages
by patching copies of the template.

The layouts of the Maggy graph's sample messages (``docs/topics.md``; names
and frames from :mod:`maglev_ros.topics`):
:func:`field_layout` (sensor_msgs/MagneticField), :func:`currents_layout`
(sensor_msgs/JointState), :func:`odometry_layout` (nav_msgs/Odometry) and
:func:`clock_layout` (rosgraph_msgs/Clock).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

from maglev_ros.cdr.layout import Path, cdr_layout
from maglev_ros.cdr.typestore import jazzy_typestore
from maglev_ros.topics import BASE_FRAME, COIL_NAMES, MAGNET_FRAME

__all__ = [
    'CURRENT_VALUES',
    'FIELD_VALUES',
    'HEADER_STAMP',
    'ODOMETRY_VALUES',
    'ESTIMATE_VALUES',
    'RawLayout',
    'clock_layout',
    'currents_layout',
    'default_message',
    'field_layout',
    'float_array_prefix',
    'odometry_layout',
    'raw_layout',
]

HEADER_STAMP: Path = ('header', 'stamp')
FIELD_VALUES: tuple[Path, ...] = tuple(('magnetic_field', a) for a in 'xyz')
CURRENT_VALUES: tuple[Path, ...] = tuple(('effort', j) for j in range(4))
ODOMETRY_VALUES: tuple[Path, ...] = (  # position, quaternion x y z w, twist (child frame)
    *(('pose', 'pose', 'position', a) for a in 'xyz'),
    *(('pose', 'pose', 'orientation', a) for a in 'xyzw'),
    *(('twist', 'twist', 'linear', a) for a in 'xyz'),
    *(('twist', 'twist', 'angular', a) for a in 'xyz'),
)
#: The estimate's Odometry: :data:`ODOMETRY_VALUES`, then the 36 pose and 36 twist covariances.
ESTIMATE_VALUES: tuple[Path, ...] = (
    *ODOMETRY_VALUES,
    *(('pose', 'covariance', i) for i in range(36)),
    *(('twist', 'covariance', i) for i in range(36)),
)
_STRINGS = ('string', 'wstring')
_NUMPY_TYPES = {'bool': np.bool_, 'byte': np.uint8, 'char': np.uint8, 'octet': np.uint8}


@dataclass(frozen=True)
class RawLayout:
    """A serialised template message and where its stamp and varying float64s sit.

    Attributes
    ----------
    template : bytes
        The CDR bytes (4-byte little-endian encapsulation header first).
    stamp_offset : int
        Byte offset of the stamp's ``sec`` (int32); ``nanosec`` (uint32) follows.
    value_offsets : tuple of int
        Byte offset of each varying float64, in the order asked for.
    """

    template: bytes
    stamp_offset: int
    value_offsets: tuple[int, ...]


def default_message(msgtype: str, typestore: Typestore | None = None):
    """Build a rosbags message of ``msgtype`` with every field zero or empty.

    Parameters
    ----------
    msgtype : str
        Message type ``pkg/msg/Type``.
    typestore : rosbags Typestore, optional
        Store that knows it (default: ROS 2 Jazzy's).

    Returns
    -------
    rosbags message
        Numbers 0, strings empty, sequences empty, fixed arrays of zeros
        (numpy arrays for primitives, as rosbags serialises them).

    Raises
    ------
    KeyError
        If the store does not know ``msgtype``.
    """
    store = typestore or jazzy_typestore()
    fields = {name: _default(store, desc) for name, desc in store.fielddefs[msgtype][1]}
    return store.types[msgtype](**fields)


def _default(store: Typestore, desc: tuple):
    kind, detail = desc
    if kind == Nodetype.NAME:
        return default_message(detail, store)
    if kind == Nodetype.BASE:
        return '' if detail[0] in _STRINGS else 0
    sub, count = detail
    if kind == Nodetype.SEQUENCE:
        count = 0
    if sub[0] == Nodetype.BASE and sub[1][0] not in _STRINGS:
        return np.zeros(count, dtype=_NUMPY_TYPES.get(sub[1][0], sub[1][0]))
    return [_default(store, sub) for _ in range(count)]


def raw_layout(
    message,
    msgtype: str,
    values: Sequence[Path],
    stamp: Path = HEADER_STAMP,
    typestore: Typestore | None = None,
) -> RawLayout:
    """Serialise ``message`` and locate its stamp and the float64 fields ``values``.

    Parameters
    ----------
    message : rosbags message
        A message of ``msgtype`` with the constant parts (frame ids, names,
        array lengths) set, e.g. from :func:`default_message`.
    msgtype : str
        Its type, ``pkg/msg/Type``.
    values : sequence of tuple
        Field paths of the varying float64 fields, e.g. ``('magnetic_field', 'x')``
        or ``('effort', 2)``.
    stamp : tuple, optional
        Path of the ``builtin_interfaces/Time`` that varies (default the header's).
    typestore : rosbags Typestore, optional
        Store that knows ``msgtype`` (default: ROS 2 Jazzy's).

    Returns
    -------
    RawLayout

    Raises
    ------
    ValueError
        If the message cannot be laid out, or a path is not a float64 of it
        (or the stamp not a Time).
    """
    store = typestore or jazzy_typestore()
    raw = bytes(store.serialize_cdr(message, msgtype))
    wanted = [(*stamp, 'sec'), (*stamp, 'nanosec'), *(tuple(v) for v in values)]
    layout = cdr_layout(store, msgtype, raw, wanted)
    if layout is None:
        raise ValueError(f'cannot locate {wanted} in a serialised {msgtype}')
    kinds = [layout.fields[w][1] for w in wanted]
    if kinds != ['<i4', '<u4'] + ['<f8'] * len(values):
        raise ValueError(
            f'cannot locate {wanted} in a serialised {msgtype} as a Time and '
            f'float64s (found {kinds})'
        )
    return RawLayout(
        raw, layout.fields[wanted[0]][0], tuple(layout.fields[w][0] for w in wanted[2:])
    )


def field_layout(frame: str) -> RawLayout:
    """Raw layout of a sensor_msgs/MagneticField in ``frame`` (3 values: x y z, T).

    Parameters
    ----------
    frame : str
        Frame id of the messages (e.g. ``maglev_sensor_0``).
    """
    msgtype = 'sensor_msgs/msg/MagneticField'
    msg = default_message(msgtype)
    msg.header.frame_id = frame
    return raw_layout(msg, msgtype, FIELD_VALUES)


def currents_layout(names: Sequence[str] = COIL_NAMES) -> RawLayout:
    """Raw layout of a sensor_msgs/JointState of 4 coils named ``names`` (4 efforts, A).

    Parameters
    ----------
    names : sequence of str, optional
        The joint names (default the coil order x+ x- y+ y-).
    """
    msgtype = 'sensor_msgs/msg/JointState'
    msg = default_message(msgtype)
    msg.name = list(names)
    msg.effort = np.zeros(len(names))
    return raw_layout(msg, msgtype, CURRENT_VALUES)


def odometry_layout(
    frame: str = BASE_FRAME,
    child_frame: str = MAGNET_FRAME,
    values: Sequence[Path] = ODOMETRY_VALUES,
) -> RawLayout:
    """Raw layout of a nav_msgs/Odometry of ``child_frame`` in ``frame``.

    By default 13 values, in the order of :data:`ODOMETRY_VALUES`: position
    (m), orientation quaternion x y z w, linear velocity in the child frame
    (m/s), angular velocity (rad/s).

    Parameters
    ----------
    frame : str, optional
        ``header.frame_id`` (default ``maglev_base``).
    child_frame : str, optional
        ``child_frame_id`` (default ``maglev_magnet``).
    values : sequence of tuple, optional
        The float64 fields that vary (e.g. :data:`ESTIMATE_VALUES`).
    """
    msgtype = 'nav_msgs/msg/Odometry'
    msg = default_message(msgtype)
    msg.header.frame_id = frame
    msg.child_frame_id = child_frame
    return raw_layout(msg, msgtype, values)


def estimate_layout(frame: str = BASE_FRAME, child_frame: str = MAGNET_FRAME) -> RawLayout:
    """Raw layout of a nav_msgs/Odometry with covariances (``maglev/state/estimate``).

    85 values, in the order of :data:`ESTIMATE_VALUES`: the 13 of
    :func:`odometry_layout`, then the row-major 6x6 pose and twist covariances.

    Parameters
    ----------
    frame : str, optional
        ``header.frame_id`` (default ``maglev_base``).
    child_frame : str, optional
        ``child_frame_id`` (default ``maglev_magnet``).
    """
    return odometry_layout(frame, child_frame, ESTIMATE_VALUES)


def clock_layout() -> RawLayout:
    """Raw layout of rosgraph_msgs/Clock (the stamp only, no values)."""
    msgtype = 'rosgraph_msgs/msg/Clock'
    return raw_layout(default_message(msgtype), msgtype, (), stamp=('clock',))


def float_array_prefix(n: int) -> bytes:
    """CDR bytes of a std_msgs/Float64MultiArray of ``n`` values, up to its data.

    The message has an empty layout (as the command topics publish it), so
    ``prefix + struct.pack(f'<{n}d', *values)`` is the whole serialised
    message (the data, a float64 sequence, is its last field).

    Parameters
    ----------
    n : int
        Number of values.

    Returns
    -------
    bytes
    """
    msgtype = 'std_msgs/msg/Float64MultiArray'
    msg = default_message(msgtype)
    msg.data = np.zeros(n)
    raw = bytes(jazzy_typestore().serialize_cdr(msg, msgtype))
    return raw[: len(raw) - 8 * n]
