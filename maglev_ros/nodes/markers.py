"""RViz markers of the platform: base components and the levitating magnet.

Cylinders in the base frame (``maglev_base``): the solenoids (copper), the
permanent magnets (grey) and the magnet at a state (red; grey after a crash),
published by the simulator on ``maglev/markers``.
"""

from __future__ import annotations

import numpy as np
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from maglev_ros.nodes import contract
from maglev_ros.physics.kernels import odometry_values

__all__ = ['base_markers', 'magnet_marker', 'marker_array']


def _color(r: float, g: float, b: float, a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=r, g=g, b=b, a=a)


def base_markers(params) -> list[Marker]:
    """Cylinder markers of the solenoids (copper) and permanent magnets (grey).

    Parameters
    ----------
    params : maglev_ros.physics.MaggyParameters
        The parameter set (cylinder centres, radii and lengths in m).

    Returns
    -------
    list of Marker
    """
    markers = []
    groups = (
        (params.solenoids, 'solenoids', _color(0.8, 0.45, 0.2)),
        (params.permanent_magnets, 'permanent_magnets', _color(0.5, 0.5, 0.55)),
    )
    for cyl, ns, color in groups:
        for i in range(cyl.count):
            m = Marker(ns=ns, id=i, type=Marker.CYLINDER, action=Marker.ADD, color=color)
            m.header.frame_id = contract.BASE_FRAME
            c = cyl.centers[i]
            m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in c)
            m.pose.orientation.w = 1.0
            m.scale.x = m.scale.y = 2.0 * float(cyl.radius[i])
            m.scale.z = float(cyl.length[i])
            markers.append(m)
    return markers


def magnet_marker(params, state: np.ndarray, crashed: bool = False) -> Marker:
    """Cylinder marker of the levitating magnet at ``state``.

    Parameters
    ----------
    params : maglev_ros.physics.MaggyParameters
        The parameter set (magnet radius and thickness in m).
    state : ndarray, shape (12,)
        Position (m) and ZYX Euler angles (rad) first.
    crashed : bool, optional
        Grey instead of red.

    Returns
    -------
    Marker
    """
    magnet = Marker(
        ns='magnet',
        id=0,
        type=Marker.CYLINDER,
        action=Marker.ADD,
        color=_color(0.3, 0.3, 0.3) if crashed else _color(0.85, 0.1, 0.1),
    )
    magnet.header.frame_id = contract.BASE_FRAME
    v = odometry_values(state)
    magnet.pose.position.x, magnet.pose.position.y, magnet.pose.position.z = v[0:3]
    o = magnet.pose.orientation
    o.x, o.y, o.z, o.w = v[3:7]
    magnet.scale.x = magnet.scale.y = 2.0 * params.magnet.radius
    magnet.scale.z = params.magnet.thickness
    return magnet


def marker_array(markers: list[Marker], stamp_ns: int) -> MarkerArray:
    """Stamp markers and wrap them in a MarkerArray.

    Parameters
    ----------
    markers : list of Marker
        The markers (stamped in place).
    stamp_ns : int
        Stamp, ns.

    Returns
    -------
    MarkerArray
    """
    sec, nanosec = contract.split_stamp(stamp_ns)
    for marker in markers:
        marker.header.stamp.sec, marker.header.stamp.nanosec = sec, nanosec
    return MarkerArray(markers=markers)
