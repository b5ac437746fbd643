"""The topic contract (``docs/topics.md``), ROS-free: names, frames, coil order, units.

Every module that names a topic, a frame, a service or a coil takes the name
from here (the nodes, the recorder, ``maglev-lab``, the bag converter's
channel units, the linear model's input labels), so the simulator, the board
driver and the tools that read their bags cannot drift apart. No rclpy import:
the ROS-free layers (``bags``, ``physics``, ``sysid``) use it as well as the
nodes. QoS and message builders are ROS code and live in
:mod:`maglev_ros.nodes.contract`.

Topics (relative names resolve in the node's namespace; ``/clock`` and
``/diagnostics`` are absolute, as ROS defines them), with publisher:

* ``maglev/sensor_<k>/field`` (MagneticField, T): driver, simulator;
* ``maglev/currents`` (JointState, A): driver, simulator;
* ``maglev/currents/command`` (JointState, A, stamped with the sample it answers):
  controller, excitation, loop;
* ``maglev/state/true`` (Odometry: m, rad, m/s, rad/s): simulator;
* ``maglev/markers`` (MarkerArray): simulator;
* ``maglev/state/estimate`` (Odometry with covariance): estimator;
* ``maglev/reference`` (PoseStamped, m): user, scripts;
* ``maglev/currents/excitation`` (JointState, A, as the command): controller, loop;
* ``maglev/identifier/model`` (Float64MultiArray, ARX coefficients): identifier;
* ``maglev/identifier/prediction_error`` (Float64MultiArray, one-step prediction
  error per output, output units): identifier;
* ``maglev/identifier/fit`` (Float64MultiArray, fit of the one-step predictions
  over a sliding window per output, percent): identifier;
* ``/clock`` (rosgraph_msgs/Clock): simulator, player;
* ``/diagnostics`` (DiagnosticArray): every node.
"""

from __future__ import annotations

__all__ = [
    'AXES',
    'BASE_FRAME',
    'CHANNEL_UNITS',
    'CLOCK_TOPIC',
    'COIL_NAMES',
    'COMMAND_TOPIC',
    'CONTROLLER_ENABLE_SERVICE',
    'CURRENTS_TOPIC',
    'DIAGNOSTICS_TOPIC',
    'ENABLE_SERVICE',
    'ESTIMATE_TOPIC',
    'FIELD_MESSAGE_TYPE',
    'EXCITATION_TOPIC',
    'IDENTIFIER_FIT_TOPIC',
    'IDENTIFIER_MODEL_TOPIC',
    'IDENTIFIER_PREDICTION_ERROR_TOPIC',
    'IDENTIFIER_RESET_SERVICE',
    'MAGNET_FRAME',
    'MARKERS_TOPIC',
    'METADATA_TOPIC',
    'MESSAGE_TYPES',
    'REFERENCE_TOPIC',
    'SIMULATOR_PAUSE_SERVICE',
    'SIMULATOR_RESET_SERVICE',
    'TRUE_STATE_TOPIC',
    'command_channel',
    'current_channel',
    'excitation_channel',
    'field_channel',
    'field_topic',
    'sensor_frame',
]

#: Solenoid order everywhere: messages, parameters, matrices.
COIL_NAMES: tuple[str, ...] = ('x+', 'x-', 'y+', 'y-')
#: Field axes of a sensor, in message order.
AXES: tuple[str, ...] = ('x', 'y', 'z')

# --------------------------------------------------------------------------- frames
BASE_FRAME = 'maglev_base'
MAGNET_FRAME = 'maglev_magnet'

# --------------------------------------------------------------------------- topics
CURRENTS_TOPIC = 'maglev/currents'
COMMAND_TOPIC = 'maglev/currents/command'
TRUE_STATE_TOPIC = 'maglev/state/true'
MARKERS_TOPIC = 'maglev/markers'
ESTIMATE_TOPIC = 'maglev/state/estimate'
REFERENCE_TOPIC = 'maglev/reference'
EXCITATION_TOPIC = 'maglev/currents/excitation'
IDENTIFIER_MODEL_TOPIC = 'maglev/identifier/model'
IDENTIFIER_PREDICTION_ERROR_TOPIC = 'maglev/identifier/prediction_error'
IDENTIFIER_FIT_TOPIC = 'maglev/identifier/fit'
CLOCK_TOPIC = '/clock'
DIAGNOSTICS_TOPIC = '/diagnostics'
#: Run metadata the bag writer adds to a bag (std_msgs/String, YAML mapping).
METADATA_TOPIC = '/maglev/metadata'

# --------------------------------------------------------------------------- services
SIMULATOR_RESET_SERVICE = 'maglev/simulator/reset'  # std_srvs/Trigger
SIMULATOR_PAUSE_SERVICE = 'maglev/simulator/pause'  # std_srvs/SetBool: true pauses
ENABLE_SERVICE = 'maglev/enable'  # std_srvs/SetBool: the driver's enable
CONTROLLER_ENABLE_SERVICE = 'maglev/controller/enable'  # std_srvs/SetBool: the controller
IDENTIFIER_RESET_SERVICE = 'maglev/identifier/reset'  # std_srvs/Trigger: restart the estimate


def field_topic(k: int) -> str:
    """Topic of sensor ``k``'s field (``maglev/sensor_<k>/field``).

    Parameters
    ----------
    k : int
        Sensor index, from 0.

    Returns
    -------
    str
    """
    return f'maglev/sensor_{k}/field'


def sensor_frame(k: int) -> str:
    """Frame id of sensor ``k`` (``maglev_sensor_<k>``).

    Parameters
    ----------
    k : int
        Sensor index, from 0.

    Returns
    -------
    str
    """
    return f'maglev_sensor_{k}'


#: Message type (``pkg/msg/Type``) of each fixed topic of the contract.
MESSAGE_TYPES: dict[str, str] = {
    CURRENTS_TOPIC: 'sensor_msgs/msg/JointState',
    COMMAND_TOPIC: 'sensor_msgs/msg/JointState',
    TRUE_STATE_TOPIC: 'nav_msgs/msg/Odometry',
    MARKERS_TOPIC: 'visualization_msgs/msg/MarkerArray',
    ESTIMATE_TOPIC: 'nav_msgs/msg/Odometry',
    REFERENCE_TOPIC: 'geometry_msgs/msg/PoseStamped',
    EXCITATION_TOPIC: 'sensor_msgs/msg/JointState',
    IDENTIFIER_MODEL_TOPIC: 'std_msgs/msg/Float64MultiArray',
    IDENTIFIER_PREDICTION_ERROR_TOPIC: 'std_msgs/msg/Float64MultiArray',
    IDENTIFIER_FIT_TOPIC: 'std_msgs/msg/Float64MultiArray',
    CLOCK_TOPIC: 'rosgraph_msgs/msg/Clock',
    DIAGNOSTICS_TOPIC: 'diagnostic_msgs/msg/DiagnosticArray',
}
FIELD_MESSAGE_TYPE = 'sensor_msgs/msg/MagneticField'  # of every field_topic(k)


# --------------------------------------------------------------------------- channels
def field_channel(k: int, axis: str) -> str:
    """Channel spec of one field axis of sensor ``k`` (T), for the bag converter.

    Parameters
    ----------
    k : int
        Sensor index.
    axis : str
        ``'x'``, ``'y'`` or ``'z'``.

    Returns
    -------
    str
        E.g. ``maglev/sensor_0/field:magnetic_field.x``.
    """
    return f'{field_topic(k)}:magnetic_field.{axis}'


def current_channel(coil: int) -> str:
    """Channel spec of coil ``coil``'s published current (A), e.g. ``...currents:effort[0]``.

    Parameters
    ----------
    coil : int
        Coil index in :data:`COIL_NAMES` order.

    Returns
    -------
    str
    """
    return f'{CURRENTS_TOPIC}:effort[{coil}]'


def command_channel(coil: int) -> str:
    """Channel spec of coil ``coil``'s commanded current (A), e.g. ``...command:effort[0]``.

    Parameters
    ----------
    coil : int
        Coil index in :data:`COIL_NAMES` order.

    Returns
    -------
    str
    """
    return f'{COMMAND_TOPIC}:effort[{coil}]'


def excitation_channel(coil: int) -> str:
    """Channel spec of coil ``coil``'s excitation part (A), e.g. ``...excitation:effort[0]``.

    Parameters
    ----------
    coil : int
        Coil index in :data:`COIL_NAMES` order.

    Returns
    -------
    str
    """
    return f'{EXCITATION_TOPIC}:effort[{coil}]'


def _absolute_pattern(topic: str) -> str:
    return '/' + topic.lstrip('/')


#: Units of the contract's channels: (absolute topic regex, field path prefix, unit).
CHANNEL_UNITS: tuple[tuple[str, str, str], ...] = (
    (_absolute_pattern(field_topic(r'\d+')), 'magnetic_field.', 'T'),
    (_absolute_pattern(CURRENTS_TOPIC), 'effort[', 'A'),
    (_absolute_pattern(COMMAND_TOPIC), 'effort[', 'A'),
    (_absolute_pattern(EXCITATION_TOPIC), 'effort[', 'A'),
    (_absolute_pattern(COMMAND_TOPIC), 'data[', 'A'),  # Float64MultiArray, older bags
    (_absolute_pattern(EXCITATION_TOPIC), 'data[', 'A'),
    *(
        (f'({_absolute_pattern(TRUE_STATE_TOPIC)}|{_absolute_pattern(ESTIMATE_TOPIC)})', p, u)
        for p, u in (
            ('pose.pose.position.', 'm'),
            ('twist.twist.linear.', 'm/s'),
            ('twist.twist.angular.', 'rad/s'),
        )
    ),
    (_absolute_pattern(REFERENCE_TOPIC), 'pose.position.', 'm'),
)
