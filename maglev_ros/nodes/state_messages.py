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

__all__ = ['UNOBSERVED_VARIANCE', 'EstimateEncoder', 'estimate_message', 'odometry_state']

#: Variance given to the unobservable yaw and yaw rate (rad^2, (rad/s)^2).
UNOBSERVED_VARIANCE = 1.0e6


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
        twist covariance over the magnet-frame velocity and the body rates
        (:func:`~maglev_ros.estimation.kernels.odometry_covariances`).
    """
    from maglev_ros.estimation.kernels import odometry_covariances

    msg = odometry_message(t_ns, x)
    pose, twist = odometry_covariances(
        np.asarray(x, dtype=float), np.asarray(cov, dtype=float), UNOBSERVED_VARIANCE
    )
    msg.pose.covariance = pose.ravel().tolist()
    msg.twist.covariance = twist.ravel().tolist()
    return msg


class EstimateEncoder:
    """Serialise estimates as ``maglev/state/estimate`` CDR bytes, ~10x faster than messages.

    The same message as :func:`estimate_message`, made by patching a
    serialised template (:func:`~maglev_ros.cdr.templates.estimate_layout`),
    for ``Publisher.publish(bytes)``.
    """

    def __init__(self) -> None:
        from maglev_ros.cdr import estimate_layout
        from maglev_ros.cdr.batch import RawMessageBatch

        self._batch = RawMessageBatch(estimate_layout())
        self._stamp = np.zeros(1, dtype=np.int64)
        self._values = np.zeros((1, self._batch.n_values))

    def encode(self, t_ns: int, x: np.ndarray, cov: np.ndarray) -> bytes:
        """Return the serialised Odometry of estimate ``x`` (see :func:`estimate_message`).

        Parameters
        ----------
        t_ns : int
            Stamp, ns (>= 0).
        x : ndarray, shape (12,)
            Estimate.
        cov : ndarray, shape (>= 10, >= 10)
            Covariance of its reduced states.
        """
        from maglev_ros.estimation.kernels import estimate_values

        estimate_values(x, cov, UNOBSERVED_VARIANCE, self._values[0])
        self._stamp[0] = t_ns
        return self._batch.serialise(self._stamp, self._values)[0]


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
