"""The estimate's Odometry: 12-state and covariance to the message and back.

Same frames and angle convention as the simulator's ``maglev/state/true``
(:func:`maglev_ros.physics.kernels.odometry_values`): pose in
``maglev_base``, ZYX Euler angles as a quaternion, linear velocity in the
magnet frame (nav_msgs puts the twist in the child frame), body rates.
"""

from __future__ import annotations

import numpy as np
from nav_msgs.msg import Odometry

from maglev_ros.nodes.messages import odometry_message

__all__ = ['UNOBSERVED_VARIANCE', 'estimate_message', 'odometry_state']

#: Variance given to the unobservable yaw and yaw rate (rad^2, (rad/s)^2).
UNOBSERVED_VARIANCE = 1.0e6


def _rotation(alpha: float, beta: float, gamma: float) -> np.ndarray:
    from maglev_ros.physics.kernels import rotation_matrix

    return np.asarray(rotation_matrix(alpha, beta, gamma))


def estimate_message(t_ns: int, x: np.ndarray, cov: np.ndarray) -> Odometry:
    """Odometry of estimate ``x`` (12,) with the covariance of its reduced states.

    Parameters
    ----------
    t_ns : int
        Stamp (the sample estimated), ns.
    x : ndarray, shape (12,)
        Position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    cov : ndarray, shape (>= 10, >= 10)
        Covariance of x y z alpha beta vx vy vz wx wy (then any bias states).

    Returns
    -------
    Odometry
        Pose covariance over x y z, rotation about x y z (yaw: unobserved);
        twist covariance over the magnet-frame velocity and the body rates.
    """
    msg = odometry_message(t_ns, x)
    p = np.asarray(cov, dtype=float)[:10, :10]
    pose = np.zeros((6, 6))
    pose[:5, :5] = p[:5, :5]
    pose[5, 5] = UNOBSERVED_VARIANCE
    rot = _rotation(float(x[3]), float(x[4]), float(x[5]))
    twist = np.zeros((6, 6))
    twist[:3, :3] = rot.T @ p[5:8, 5:8] @ rot
    cross = rot.T @ p[5:8, 8:10]
    twist[:3, 3:5] = cross
    twist[3:5, :3] = cross.T
    twist[3:5, 3:5] = p[8:10, 8:10]
    twist[5, 5] = UNOBSERVED_VARIANCE
    msg.pose.covariance = pose.ravel().tolist()
    msg.twist.covariance = twist.ravel().tolist()
    return msg


def odometry_state(msg: Odometry) -> np.ndarray:
    """Return the 12-state of a ``maglev/state/true`` or ``maglev/state/estimate`` Odometry.

    Parameters
    ----------
    msg : Odometry
        The message.

    Returns
    -------
    ndarray, shape (12,)
        Position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    """
    from maglev_ros.physics.kernels import odometry_state_values

    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    v, w = msg.twist.twist.linear, msg.twist.twist.angular
    return odometry_state_values((p.x, p.y, p.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z, w.x, w.y, w.z))
