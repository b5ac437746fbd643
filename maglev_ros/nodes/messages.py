"""Message builders of the Maggy graph: plain message objects (tests, slow paths).

The 5 kHz paths publish serialised bytes instead (raw layouts in
:mod:`maglev_ros.nodes.contract`, bursts in :mod:`maglev_ros.nodes.cdr_batch`).
Frames and coil names come from :mod:`maglev_ros.topics`; the true state's
numbers from :func:`maglev_ros.physics.kernels.odometry_values`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.topics import BASE_FRAME, COIL_NAMES, MAGNET_FRAME, sensor_frame

__all__ = [
    'CommandMessageError',
    'command_currents',
    'command_message',
    'currents_message',
    'diagnostic_array',
    'field_message',
    'odometry_message',
    'split_stamp',
    'stamp_ns',
]


def split_stamp(t_ns: int) -> tuple[int, int]:
    """Split a time in ns into (sec, nanosec).

    Parameters
    ----------
    t_ns : int
        Time, ns.
    """
    return t_ns // 1_000_000_000, t_ns % 1_000_000_000


def stamp_ns(msg) -> int:
    """Return a stamped message's header stamp in ns (the inverse of :func:`split_stamp`).

    Parameters
    ----------
    msg : message with a ``std_msgs/Header`` ``header``
        E.g. MagneticField, JointState, Odometry.
    """
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


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
    """MagneticField of sensor ``k`` at time ``t_ns`` (ns) with ``field_t`` (3,) in T.

    Parameters
    ----------
    k : int
        Sensor index.
    t_ns : int
        Stamp, ns.
    field_t : sequence of float, shape (3,)
        Field, T.
    """
    msg = MagneticField()
    msg.header.frame_id = sensor_frame(k)
    _set_field(msg, field_t)
    return _stamp(msg, t_ns)


def currents_message(t_ns: int, currents: Sequence[float]) -> JointState:
    """JointState of the coil currents (4,) in A (effort), names x+ x- y+ y-.

    Parameters
    ----------
    t_ns : int
        Stamp, ns.
    currents : sequence of float, shape (4,)
        Coil currents x+ x- y+ y-, A.
    """
    msg = JointState(name=list(COIL_NAMES))
    _set_effort(msg, currents)
    return _stamp(msg, t_ns)


class CommandMessageError(ValueError):
    """A command message does not name the coils in the contract's order."""


def command_message(t_ns: int, currents: Sequence[float]) -> JointState:
    """Return a coil command (``maglev/currents/command``, ``.../excitation``): JointState, A.

    Parameters
    ----------
    t_ns : int
        Stamp of the sample the command answers, ns.
    currents : sequence of float, shape (4,)
        Commanded currents x+ x- y+ y-, A (``effort``).
    """
    return currents_message(t_ns, currents)


def command_currents(msg: JointState) -> np.ndarray:
    """Return a command's currents, A, in :data:`~maglev_ros.topics.COIL_NAMES` order.

    Their count and values are the consumer's to check (the board's command
    guard and the simulator count what they refuse).

    Parameters
    ----------
    msg : JointState
        A command (:func:`command_message`). Without names, or with the
        coils' names in the contract's order, the efforts are taken as they
        are; other names must be the coils' in another order (one per effort).

    Raises
    ------
    CommandMessageError
        If the names are not the coils'.
    """
    effort = np.asarray(msg.effort, dtype=float)
    names = list(msg.name)
    if not names or names == list(COIL_NAMES):
        return effort
    if sorted(names) != sorted(COIL_NAMES) or len(names) != effort.size:
        raise CommandMessageError(
            f'a command names the coils {list(COIL_NAMES)}, one effort each; got names '
            f'{names} and {effort.size} efforts'
        )
    return effort[[names.index(c) for c in COIL_NAMES]]


def odometry_message(t_ns: int, x: np.ndarray) -> Odometry:
    """True-state Odometry of state ``x`` (12,): frame maglev_base, child maglev_magnet.

    Parameters
    ----------
    t_ns : int
        Stamp, ns.
    x : ndarray, shape (12,)
        State: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    """
    msg = Odometry()
    msg.header.frame_id = BASE_FRAME
    msg.child_frame_id = MAGNET_FRAME
    from maglev_ros.physics.kernels import odometry_values  # numba: only where used

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
