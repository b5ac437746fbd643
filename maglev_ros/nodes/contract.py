"""The shared node contract's ROS side: QoS profiles, message builders, running nodes.

Names, frames and coil order are ROS-free, in :mod:`maglev_ros.topics`
(re-exported here). Every node that talks on the Maggy graph takes its QoS
from here, so the simulator and the board driver cannot drift apart.

QoS (as the driver's docstring states it):

* sensor streams (fields, currents, true state, ``/clock``): RELIABLE,
  KEEP_LAST 1000 - every sample must arrive for identification; 1000 samples
  are 0.2 s at 5 kHz;
* commands (real time): BEST_EFFORT, KEEP_LAST 10 - matches both reliable and
  best-effort publishers; a stale command is worth nothing;
* commands (lockstep simulation): RELIABLE, KEEP_LAST 1000 - every command
  drives exactly one sample, so none may be lost (a reliable publisher, as
  the excitation node's, is then required);
* markers: RELIABLE, KEEP_LAST 1 (RViz's default); diagnostics: KEEP_LAST 10.

Message builders come in two kinds: plain ones returning message objects
(tests, slow paths), and raw layouts (``*_layout``: a message serialised once,
with the byte offsets of its stamp and varying float64 fields) for publishing
at 5 kHz with ``publish(bytes)``: :class:`RawTemplate` patches them one
message at a time, :mod:`maglev_ros.nodes.cdr_batch` a burst of samples at
once.
"""

from __future__ import annotations

import math
import os
import struct
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.bags.cdr_layout import cdr_layout
from maglev_ros.bags.typestore import jazzy_typestore
from maglev_ros.nodes.params import help_requested
from maglev_ros.nodes.scheduling import relax_event_threads
from maglev_ros.topics import (  # re-exported: the nodes' one import of the contract
    BASE_FRAME,
    CLOCK_TOPIC,
    COIL_NAMES,
    COMMAND_TOPIC,
    CURRENTS_TOPIC,
    DIAGNOSTICS_TOPIC,
    MAGNET_FRAME,
    MARKERS_TOPIC,
    TRUE_STATE_TOPIC,
    field_topic,
    sensor_frame,
)

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
    'euler_to_quaternion',
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
    'odometry_values',
    'raw_layout',
    'sensor_frame',
    'split_stamp',
]

SENSOR_QOS = QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)
COMMAND_QOS = QoSProfile(
    depth=10, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST
)
LOCKSTEP_COMMAND_QOS = QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)
MARKERS_QOS = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    durability=DurabilityPolicy.VOLATILE,
)
DIAGNOSTICS_QOS = QoSProfile(depth=10)


def split_stamp(t_ns: int) -> tuple[int, int]:
    """Split a time in ns into (sec, nanosec)."""
    return t_ns // 1_000_000_000, t_ns % 1_000_000_000


# --------------------------------------------------------------------------- conversions
def euler_to_quaternion(alpha: float, beta: float, gamma: float) -> tuple[float, ...]:
    """Quaternion (x, y, z, w) of ``R = Rz(gamma) Ry(beta) Rx(alpha)`` (angles in rad)."""
    ca, sa = math.cos(alpha / 2), math.sin(alpha / 2)
    cb, sb = math.cos(beta / 2), math.sin(beta / 2)
    cg, sg = math.cos(gamma / 2), math.sin(gamma / 2)
    return (
        sa * cb * cg - ca * sb * sg,
        ca * sb * cg + sa * cb * sg,
        ca * cb * sg - sa * sb * cg,
        ca * cb * cg + sa * sb * sg,
    )


def odometry_values(x: np.ndarray) -> np.ndarray:
    """Return the 13 varying numbers of the true-state Odometry of state ``x``.

    Parameters
    ----------
    x : ndarray, shape (12,)
        State: position (m), ZYX Euler angles (rad), world velocity (m/s),
        body rates (rad/s).

    Returns
    -------
    ndarray, shape (13,)
        Position (3), quaternion x y z w (4), linear velocity in the magnet
        frame (3, nav_msgs puts the twist in the child frame), body rates (3).
    """
    alpha, beta, gamma = float(x[3]), float(x[4]), float(x[5])
    ca, sa = math.cos(alpha), math.sin(alpha)
    cb, sb = math.cos(beta), math.sin(beta)
    cg, sg = math.cos(gamma), math.sin(gamma)
    rot = np.array(
        [  # Rz Ry Rx, body to world
            [cg * cb, cg * sb * sa - sg * ca, cg * sb * ca + sg * sa],
            [sg * cb, sg * sb * sa + cg * ca, sg * sb * ca - cg * sa],
            [-sb, cb * sa, cb * ca],
        ]
    )
    out = np.empty(13)
    out[0:3] = x[0:3]
    out[3:7] = euler_to_quaternion(alpha, beta, gamma)
    out[7:10] = rot.T @ np.asarray(x[6:9], dtype=float)
    out[10:13] = x[9:12]
    return out


# --------------------------------------------------------------------------- messages
def _set_field(msg: MagneticField, values: Sequence[float]) -> None:
    msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = (float(v) for v in values)


def _set_effort(msg: JointState, values: Sequence[float]) -> None:
    msg.effort = [float(v) for v in values]


def _set_odometry(msg: Odometry, values: Sequence[float]) -> None:
    v = [float(a) for a in values]
    pose, twist = msg.pose.pose, msg.twist.twist
    pose.position.x, pose.position.y, pose.position.z = v[0:3]
    o = pose.orientation
    o.x, o.y, o.z, o.w = v[3:7]
    twist.linear.x, twist.linear.y, twist.linear.z = v[7:10]
    twist.angular.x, twist.angular.y, twist.angular.z = v[10:13]


def _stamp(msg, t_ns: int):
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_stamp(int(t_ns))
    return msg


def field_message(k: int, t_ns: int, field_t: Sequence[float]) -> MagneticField:
    """MagneticField of sensor ``k`` at time ``t_ns`` (ns) with ``field_t`` (3,) in T."""
    msg = MagneticField()
    msg.header.frame_id = sensor_frame(k)
    _set_field(msg, field_t)
    return _stamp(msg, t_ns)


def currents_message(t_ns: int, currents: Sequence[float]) -> JointState:
    """JointState of the coil currents (4,) in A (effort), names x+ x- y+ y-."""
    msg = JointState(name=list(COIL_NAMES))
    _set_effort(msg, currents)
    return _stamp(msg, t_ns)


def odometry_message(t_ns: int, x: np.ndarray) -> Odometry:
    """True-state Odometry of state ``x`` (12,): frame maglev_base, child maglev_magnet."""
    msg = Odometry()
    msg.header.frame_id = BASE_FRAME
    msg.child_frame_id = MAGNET_FRAME
    _set_odometry(msg, odometry_values(x))
    return _stamp(msg, t_ns)


def diagnostic_array(
    t_ns: int,
    name: str,
    level: int,
    message: str,
    values: Mapping[str, object],
    hardware_id: str = '',
) -> DiagnosticArray:
    """One-status DiagnosticArray.

    Parameters
    ----------
    t_ns : int
        Stamp, ns.
    name, message, hardware_id : str
        Status fields.
    level : int
        ``DiagnosticStatus.OK``, ``WARN``, ``ERROR`` or ``STALE`` (bytes or int).
    values : mapping
        Key/value pairs (values converted with ``str``).

    Returns
    -------
    DiagnosticArray
    """
    status = DiagnosticStatus(
        level=level if isinstance(level, bytes) else bytes([level]),
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()],
    )
    return _stamp(DiagnosticArray(status=[status]), t_ns)


# --------------------------------------------------------------------------- running
def make_executor(context=None):
    """Return the fastest executor available: EventsExecutor, else SingleThreadedExecutor."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # older rclpy
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    return EventsExecutor(context=context)


def spin(executor, context=None, stop=None) -> None:
    """Spin ``executor`` until its context shuts down or ``stop`` is set.

    Runs ``spin_once`` in a loop: the Jazzy EventsExecutor's own ``spin()``
    does not fire timers in the PyPI build, ``spin_once`` does.

    Parameters
    ----------
    executor : rclpy executor
        The executor (nodes added).
    context : rclpy.context.Context, optional
        Its context (default: the default context).
    stop : threading.Event, optional
        Set it to end the loop from another thread.
    """
    context = context or rclpy.get_default_context()
    while context.ok() and not (stop is not None and stop.is_set()):
        try:
            executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            break
        except Exception:  # noqa: BLE001 - re-raised unless the context is gone
            if context.ok():
                raise
            break  # a callback raced the shutdown (SIGINT/SIGTERM): nothing left to do


class Spinner:
    """Spin nodes on one executor in a background thread (tests, ``maglev-lab``).

    Parameters
    ----------
    context : rclpy.context.Context
        The nodes' context.
    nodes : sequence of Node
        Nodes to spin.
    """

    def __init__(self, context, nodes) -> None:
        import threading

        self.context = context
        relax_event_threads()
        self.executor = make_executor(context)
        for node in nodes:
            self.executor.add_node(node)
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=spin,
            args=(self.executor, context, self._stop),
            name='maglev-spinner',
            daemon=True,
        )
        self._thread.start()

    def add_node(self, node) -> None:
        """Add a node to the executor."""
        self.executor.add_node(node)

    def close(self) -> None:
        """Stop spinning and shut the executor down (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=10.0)
        self.executor.shutdown()


def run_nodes(factories, args: list[str] | None, name: str, errors: tuple, parameters=None) -> int:
    """Init rclpy, build nodes, spin them on one executor until SIGINT/SIGTERM.

    Parameters
    ----------
    factories : sequence of callable
        Each returns a node (called after ``rclpy.init``).
    args : list of str or None
        Command-line arguments (ROS arguments included; None: ``sys.argv``).
    name : str
        Logger name for parameter errors.
    errors : tuple of exception types
        Parameter errors: logged in one line, exit status 2.
    parameters : maglev_ros.nodes.params.ParameterTable, optional
        The node's parameters: ``--help`` (``-h``) before ``--ros-args``
        prints them and returns 0 without starting ROS.

    Returns
    -------
    int
        0, or 2 for invalid parameters or ROS arguments.
    """
    if parameters is not None and help_requested(args):
        argv = sys.argv if args is None else args
        prog = (
            os.path.splitext(os.path.basename(argv[0]))[0]
            if argv and not argv[0].startswith('-')
            else None
        )
        print(parameters.help_text(prog), end='')
        return 0
    try:
        rclpy.init(args=args)
    except Exception as err:  # noqa: BLE001 - rcl refuses the command line (RCLError)
        text = str(err).strip().splitlines()
        print(f'{name}: error: {text[0] if text else type(err).__name__}', file=sys.stderr)
        return 2
    nodes = []
    executor = None
    try:
        for factory in factories:
            nodes.append(factory())
        relax_event_threads()  # DDS timer wake-ups must not preempt the publishers
        executor = make_executor()
        for node in nodes:
            executor.add_node(node)
        spin(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except errors as err:
        rclpy.logging.get_logger(name).error(str(err))
        return 2
    finally:
        if executor is not None:
            executor.shutdown()
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


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
