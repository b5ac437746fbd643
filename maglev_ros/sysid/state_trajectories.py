"""State trajectories from a bag: the 12-state of an Odometry topic and the coil currents.

For SINDy (:func:`maglev_ros.sysid.sindy.sindy`) on recorded sessions: the
simulator's true state (``maglev/state/true``) or an estimator's estimate
(``maglev/state/estimate``) as the package publishes them (position, the
ZYX Euler angles as a quaternion, the velocity in the magnet frame, body
rates), turned back into the package's 12-state
(:func:`maglev_ros.physics.kernels.odometry_state_values`), on the bag's
common time base with the measured coil currents.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..topics import TRUE_STATE_TOPIC

__all__ = ['ODOMETRY_FIELDS', 'StateTrajectory', 'bag_states']

#: The 13 Odometry fields in the order of ``odometry_state_values``.
ODOMETRY_FIELDS = (
    'pose.pose.position.x',
    'pose.pose.position.y',
    'pose.pose.position.z',
    'pose.pose.orientation.x',
    'pose.pose.orientation.y',
    'pose.pose.orientation.z',
    'pose.pose.orientation.w',
    'twist.twist.linear.x',
    'twist.twist.linear.y',
    'twist.twist.linear.z',
    'twist.twist.angular.x',
    'twist.twist.angular.y',
    'twist.twist.angular.z',
)


@dataclass(frozen=True)
class StateTrajectory:
    """States and inputs on one time base.

    Attributes
    ----------
    x : ndarray, shape (N, 12)
        Position (m), ZYX Euler angles (rad), world velocity (m/s), body rates (rad/s).
    u : ndarray, shape (N, n_coils)
        Coil currents, A.
    dt : float
        Sample time, s.
    """

    x: np.ndarray
    u: np.ndarray
    dt: float


def bag_states(
    path: str | Path,
    topic: str = TRUE_STATE_TOPIC,
    currents: tuple[str, ...] | None = None,
) -> StateTrajectory:
    """Read an Odometry topic's 12-state and the coil currents from a bag.

    Parameters
    ----------
    path : str or Path
        rosbag2 bag directory.
    topic : str
        Odometry topic (``maglev/state/true`` or ``maglev/state/estimate``).
    currents : tuple of str, optional
        Input channel specs (default: the four published coil currents).

    Returns
    -------
    StateTrajectory
        States, currents and sample time.
    """
    from ..bags import load_bag_dataset
    from ..physics.kernels import odometry_state_values
    from ..topics import current_channel

    channels = [f'{topic}:{field}' for field in ODOMETRY_FIELDS]
    inputs = list(currents) if currents else [current_channel(k) for k in range(4)]
    data = load_bag_dataset(path, outputs=channels, inputs=inputs)
    x = np.array([odometry_state_values(row) for row in data.y])
    return StateTrajectory(x, np.asarray(data.u, dtype=float), float(data.Ts))
