"""Bags for the tests: messages built and serialised with rclpy, written with BagWriter."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import Float64MultiArray

from maglev_ros.bags import BagWriter

T0_NS = 1_700_000_000_123_000_000  # an epoch-like start, ns
TS = 2e-4  # 5 kHz, s
TS_NS = 200_000

SENSOR = '/maglev/sensor_0/field'
CURRENTS = '/maglev/currents'
COMMAND = '/maglev/currents/command'
METADATA = {
    'params': 'maggy_v4',
    'model': 'fast',
    'seed': 42,
    'version': '0.1.0',
    'rate_hz': 5000.0,
    'lockstep': True,
}


def field_msg(stamp_ns: int, b: np.ndarray) -> bytes:
    msg = MagneticField()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    msg.header.frame_id = 'maglev_sensor_0'
    msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = (float(v) for v in b)
    return serialize_message(msg)


def currents_msg(stamp_ns: int, i: np.ndarray) -> bytes:
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    msg.name = ['x+', 'x-', 'y+', 'y-']
    msg.effort = [float(v) for v in i]
    return serialize_message(msg)


def command_msg(u: np.ndarray) -> bytes:
    msg = Float64MultiArray()
    msg.data = [float(v) for v in u]
    return serialize_message(msg)


def stamped_command_msg(stamp_ns: int, u: np.ndarray) -> bytes:
    """A command as JointState: effort in A, stamped with the sample it answers."""
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    msg.header.frame_id = 'maglev'
    msg.name = ['x+', 'x-', 'y+', 'y-']
    msg.effort = [float(v) for v in u]
    return serialize_message(msg)


@dataclass(frozen=True)
class Lockstep:
    """What a lockstep run published: sample k at T0 + k Ts on every topic."""

    stamps: np.ndarray  # (n,) int64 ns
    field: np.ndarray  # (n, 3) T
    currents: np.ndarray  # (n, 4) A
    command: np.ndarray  # (n, 4) A


def lockstep_data(n: int, seed: int = 1) -> Lockstep:
    rng = np.random.default_rng(seed)
    stamps = T0_NS + np.arange(n, dtype=np.int64) * TS_NS
    command = rng.uniform(-1.0, 1.0, (n, 4))
    currents = 0.9 * command + rng.normal(0.0, 1e-3, (n, 4))
    field = rng.normal(0.0, 1e-3, (n, 3)) + np.array([1e-3, -2e-3, 5e-2])
    return Lockstep(stamps, field, currents, command)


def write_lockstep_bag(
    path: Path,
    run: Lockstep,
    storage: str = 'mcap',
    drop: dict[str, list[int]] | None = None,
    command_delay_ns: int = 0,
    metadata: dict | None = None,
    log: dict[str, list] | None = None,
    stamped_commands: bool = False,
) -> Path:
    """Write a lockstep run: sensor and currents stamped, commands by log time.

    ``stamped_commands``: commands as JointState stamped with their sample (logged
    at the stamp plus ``command_delay_ns``), else Float64MultiArray (older bags).

    ``drop`` maps a topic to sample indices not written (dropped samples);
    ``log`` (if given) collects ``(log time, bytes)`` per topic as written.
    """
    drop = drop or {}
    log = {} if log is None else log

    def write(handle, stamp, raw):
        log.setdefault(handle.name, []).append((stamp, raw))
        bag.write(handle, stamp, raw)

    with BagWriter(
        path, storage=storage, metadata=METADATA if metadata is None else metadata
    ) as bag:
        sensor = bag.add_topic(SENSOR, 'sensor_msgs/msg/MagneticField')
        currents = bag.add_topic(CURRENTS, 'sensor_msgs/msg/JointState')
        command_type = (
            'sensor_msgs/msg/JointState' if stamped_commands else 'std_msgs/msg/Float64MultiArray'
        )
        command = bag.add_topic(COMMAND, command_type)
        for k, stamp in enumerate(run.stamps):
            # log time: received a little after the sample time (like a real recorder)
            if k not in drop.get(SENSOR, ()):
                write(sensor, int(stamp) + 30_000, field_msg(stamp, run.field[k]))
            if k not in drop.get(CURRENTS, ()):
                write(currents, int(stamp) + 40_000, currents_msg(stamp, run.currents[k]))
            if k not in drop.get(COMMAND, ()):
                raw = (
                    stamped_command_msg(stamp, run.command[k])
                    if stamped_commands
                    else command_msg(run.command[k])
                )
                write(command, int(stamp) + command_delay_ns, raw)
    return path
