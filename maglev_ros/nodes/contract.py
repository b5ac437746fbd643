"""The nodes' contract: raw CDR layouts, and one import for the contract's parts.

Names, frames and coil order are ROS-free, in :mod:`maglev_ros.topics`; QoS
in :mod:`maglev_ros.nodes.qos`; message builders in
:mod:`maglev_ros.nodes.messages`; executors and ``main`` in
:mod:`maglev_ros.nodes.runtime`. They are re-exported here for the nodes
that import the contract as one module.

Raw layouts (``*_layout``: a message serialised once, with the byte offsets of
its stamp and varying float64 fields) are for publishing at 5 kHz with
``publish(bytes)``: :class:`RawTemplate` patches them one message at a time,
:mod:`maglev_ros.nodes.cdr_batch` a burst of samples at once.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.bags.cdr_layout import cdr_layout
from maglev_ros.bags.typestore import jazzy_typestore
from maglev_ros.nodes.messages import (
    currents_message,
    diagnostic_array,
    field_message,
    odometry_message,
    split_stamp,
)
from maglev_ros.nodes.qos import (
    COMMAND_QOS,
    DIAGNOSTICS_QOS,
    LOCKSTEP_COMMAND_QOS,
    MARKERS_QOS,
    SENSOR_QOS,
)
from maglev_ros.nodes.runtime import Spinner, make_executor, run_nodes, spin
from maglev_ros.topics import (
    BASE_FRAME,
    CLOCK_TOPIC,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    DIAGNOSTICS_TOPIC,
    MAGNET_FRAME,
    MARKERS_TOPIC,
    TRUE_STATE_TOPIC,
    field_topic,
    sensor_frame,
)
from maglev_ros.topics import COIL_NAMES as _COIL_ORDER

__all__ = [
    'BASE_FRAME',
    'CLOCK_TOPIC',
    'COIL_NAMES',
    'COMMAND_QOS',
    'COMMAND_TOPIC',
    'CURRENTS_TOPIC',
    'DIAGNOSTICS_QOS',
    'DIAGNOSTICS_TOPIC',
    'LOCKSTEP_COMMAND_QOS',
    'MAGNET_FRAME',
    'MARKERS_QOS',
    'MARKERS_TOPIC',
    'SENSOR_QOS',
    'TRUE_STATE_TOPIC',
    'CURRENT_VALUES',
    'FIELD_VALUES',
    'HEADER_STAMP',
    'ODOMETRY_VALUES',
    'RawLayout',
    'RawTemplate',
    'clock_template',
    'currents_layout',
    'currents_message',
    'currents_template',
    'diagnostic_array',
    'field_layout',
    'field_message',
    'field_template',
    'make_executor',
    'Spinner',
    'run_nodes',
    'spin',
    'field_topic',
    'odometry_layout',
    'odometry_message',
    'odometry_template',
    'raw_layout',
    'sensor_frame',
    'split_stamp',
]


COIL_NAMES = list(_COIL_ORDER)  # as JointState.name holds it


def __getattr__(name: str):
    # moved next to kernels.rotation_matrix; imported on use (numba) for callers of old
    if name in ('odometry_values', 'euler_to_quaternion'):
        from maglev_ros.physics import kernels

        return getattr(kernels, name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


# --------------------------------------------------------------------------- raw CDR
Path = tuple[str | int, ...]  # a field path, as maglev_ros.bags.cdr_layout takes it
HEADER_STAMP: Path = ('header', 'stamp')
FIELD_VALUES: tuple[Path, ...] = tuple(('magnetic_field', a) for a in 'xyz')
CURRENT_VALUES: tuple[Path, ...] = tuple(('effort', j) for j in range(4))
ODOMETRY_VALUES: tuple[Path, ...] = (  # the order of odometry_values
    *(('pose', 'pose', 'position', a) for a in 'xyz'),
    *(('pose', 'pose', 'orientation', a) for a in 'xyzw'),
    *(('twist', 'twist', 'linear', a) for a in 'xyz'),
    *(('twist', 'twist', 'angular', a) for a in 'xyz'),
)


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


def raw_layout(template, values: Sequence[Path], stamp: Path = HEADER_STAMP) -> RawLayout:
    """Serialise ``template`` and locate its stamp and the float64 fields ``values``.

    The bytes are laid out by the bag converter's CDR walker
    (:func:`maglev_ros.bags.cdr_layout.cdr_layout`, over ROS 2 Jazzy's
    message definitions): one piece of code knows where fields sit in CDR,
    for reading bags and for publishing bytes.

    Parameters
    ----------
    template : message
        A message with the constant parts (frame ids, names, array lengths) set.
    values : sequence of tuple
        Field paths of the varying float64 fields, e.g. ``('magnetic_field', 'x')``
        or ``('effort', 2)``.
    stamp : tuple, optional
        Path of the ``builtin_interfaces/Time`` that varies (default the header's).

    Returns
    -------
    RawLayout

    Raises
    ------
    ValueError
        If the message cannot be laid out, or a path is not a float64 of it
        (or the stamp not a Time).
    """
    raw = bytes(serialize_message(template))
    cls = type(template)
    msgtype = f'{cls.__module__.split(".")[0]}/msg/{cls.__name__}'
    wanted = [(*stamp, 'sec'), (*stamp, 'nanosec'), *(tuple(v) for v in values)]
    layout = cdr_layout(jazzy_typestore(), msgtype, raw, wanted)
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


class RawTemplate:
    """Serialise messages of one type that differ only in stamp and some float64 fields.

    :meth:`serialise` patches a copy of the template's bytes with ``struct``
    at the offsets of a :class:`RawLayout`, which is several times cheaper
    than building and converting a message object (one message at a time;
    :class:`maglev_ros.nodes.cdr_batch.SampleSerialiser` does bursts).

    Parameters
    ----------
    layout : RawLayout
        The serialised template and its offsets.
    """

    def __init__(self, layout: RawLayout) -> None:
        offsets = layout.value_offsets
        n_values = len(offsets)
        self._stamp_at = layout.stamp_offset
        self._runs: list[tuple[int, int, struct.Struct]] = []  # (offset, first, packer)
        j = 0
        while j < n_values:
            end = j + 1
            while end < n_values and offsets[end] == offsets[end - 1] + 8:
                end += 1
            self._runs.append((offsets[j], j, struct.Struct(f'<{end - j}d')))
            j = end
        self._template = layout.template
        self._stamp_packer = struct.Struct('<iI')
        self.n_values = n_values
        self.size = len(layout.template)

    def serialise(self, t_ns: int, values: Sequence[float] = ()) -> bytes:
        """CDR bytes of one message stamped ``t_ns`` (ns) with ``values`` (n_values,)."""
        buf = bytearray(self._template)
        self._stamp_packer.pack_into(
            buf, self._stamp_at, t_ns // 1_000_000_000, t_ns % 1_000_000_000
        )
        for offset, first, packer in self._runs:
            packer.pack_into(buf, offset, *values[first : first + packer.size // 8])
        return bytes(buf)


def field_layout(frame: str) -> RawLayout:
    """Raw layout of a MagneticField in ``frame`` (3 values, T)."""
    msg = MagneticField()
    msg.header.frame_id = frame
    return raw_layout(msg, FIELD_VALUES)


def currents_layout() -> RawLayout:
    """Raw layout of the currents JointState (4 efforts, A)."""
    return raw_layout(JointState(name=list(COIL_NAMES), effort=[0.0] * 4), CURRENT_VALUES)


def odometry_layout() -> RawLayout:
    """Raw layout of the true-state Odometry (13 values of :func:`odometry_values`)."""
    msg = Odometry()
    msg.header.frame_id = BASE_FRAME
    msg.child_frame_id = MAGNET_FRAME
    return raw_layout(msg, ODOMETRY_VALUES)


def field_template(k: int) -> RawTemplate:
    """Raw template of sensor ``k``'s MagneticField (3 values, T)."""
    return RawTemplate(field_layout(sensor_frame(k)))


def currents_template() -> RawTemplate:
    """Raw template of the currents JointState (4 efforts, A)."""
    return RawTemplate(currents_layout())


def odometry_template() -> RawTemplate:
    """Raw template of the true-state Odometry (13 values of :func:`odometry_values`)."""
    return RawTemplate(odometry_layout())


def clock_template() -> RawTemplate:
    """Raw template of rosgraph_msgs/Clock (stamp only)."""
    return RawTemplate(raw_layout(Clock(), (), stamp=('clock',)))
