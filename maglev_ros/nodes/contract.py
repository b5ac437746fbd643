"""The nodes' contract: one import for the contract's parts.

Names, frames and coil order are ROS-free, in :mod:`maglev_ros.topics`; QoS
in :mod:`maglev_ros.nodes.qos`; message builders in
:mod:`maglev_ros.nodes.messages`; executors and ``main`` in
:mod:`maglev_ros.nodes.runtime`. They are re-exported here for the nodes
that import the contract as one module.

The 5 kHz sample messages are published as raw CDR bytes, a burst of samples
at once: the layouts and serialisers are ROS-free, in :mod:`maglev_ros.cdr`.
"""

from __future__ import annotations

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
    'currents_message',
    'diagnostic_array',
    'field_message',
    'make_executor',
    'Spinner',
    'run_nodes',
    'spin',
    'field_topic',
    'odometry_message',
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
