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

Message builders return message objects (tests, slow paths); the 5 kHz
sample messages are published as raw CDR bytes, a burst of samples at once
(:mod:`maglev_ros.cdr`: the layouts in ``templates``, the serialisers in
``batch``).
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Mapping, Sequence

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState, MagneticField

from maglev_ros.nodes.params import help_requested
from maglev_ros.nodes.scheduling import relax_event_threads
from maglev_ros.stop_signals import StopSignals
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
    'currents_message',
    'diagnostic_array',
    'euler_to_quaternion',
    'field_message',
    'make_executor',
    'Spinner',
    'run_nodes',
    'spin',
    'field_topic',
    'odometry_message',
    'odometry_values',
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


def drain(executor, context=None, seconds: float = 0.1) -> None:
    """Run the callbacks already due (messages received before a stop), for ``seconds``.

    Parameters
    ----------
    executor : rclpy executor
        The executor (nodes added).
    context : rclpy.context.Context, optional
        Its context (default: the default context).
    seconds : float
        How long to keep spinning, s.
    """
    context = context or rclpy.get_default_context()
    deadline = time.monotonic() + seconds
    while context.ok() and time.monotonic() < deadline:
        try:
            executor.spin_once(timeout_sec=0.01)
        except ExternalShutdownException:
            break


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
    """Init rclpy, build nodes, spin them on one executor until SIGINT/SIGTERM/SIGHUP.

    A second signal during the clean-up is ignored: the nodes are destroyed
    (bags finalised, coils zeroed) before the context shuts down, and the
    exit status stays 0.

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
    # SIGINT, SIGTERM and SIGHUP end the spin; one arriving during the clean-up
    # (launch's own SIGINT after a terminal's Ctrl-C) no longer interrupts it:
    # rclpy's handlers are off, so the context stays valid until the nodes are
    # destroyed (bags finalised, coils zeroed) and is shut down last
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # noqa: BLE001 - rcl refuses the command line (RCLError)
        text = str(err).strip().splitlines()
        print(f'{name}: error: {text[0] if text else type(err).__name__}', file=sys.stderr)
        return 2
    nodes = []
    executor = None
    with StopSignals() as stop:
        try:
            for factory in factories:
                nodes.append(factory())
            relax_event_threads()  # DDS timer wake-ups must not preempt the publishers
            executor = make_executor()
            for node in nodes:
                executor.add_node(node)
            spin(executor, stop=stop.event)
            drain(executor)  # what arrived before the signal goes into the bag
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
