"""Compiled (numba) kernels of the fast model.

Field sums, force and torque, 12-state dynamics, sensor model and the
fixed-step integrator.

Everything here works on plain arrays so that one compiled call does a whole
integration step without Python overhead. The public, documented API is in
:mod:`maglev_ros.physics.model`; these functions are its engine.

Packed arguments (few arrays, so that a call from Python costs little):

``src`` (S, 6)
    one row per base loop: centre x, y, z (m), radius (m), fixed current (A),
    coil gain (turns); with ``coil`` (S,) int64, the input feeding the loop
    (-1: none), the loop current is ``src[j, 4] + src[j, 5] * u[coil[j]]``.
``rim`` (2, n)
    cos and sin of the rim angles of the levitating magnet.
``par`` (9,)
    rim radius R (m), quadrature weight R l 2 pi / n (m^2), K0 = -J / mu0 (A/m),
    mass (kg), Ixx, Iyy, Izz (kg m^2), torque mode, kinematics (as floats).
``sens`` (k, 18)
    per sensor: position (3, m), mounting rotation (9, row-major, sensor to
    world), gain (3), offset (3, T); ``mag`` (2,): the magnet's own loop radius (m)
    and current (A) for the sensor model.
``work`` (WORK_ROWS, >= n S)
    scratch space owned by the model.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .loop import FASTMATH, LOOP_WORK_ROWS, loop_batch

__all__ = [
    'euler_to_quaternion',
    'odometry_fill',
    'odometry_round_trip',
    'odometry_state_values',
    'odometry_values',
    'rotation_matrix',
    'WORK_ROWS',
    'TORQUE_TRUE',
    'TORQUE_PUBLISHED',
    'KINEMATICS_RIGID',
    'KINEMATICS_PUBLISHED',
    'COIL_IDEAL',
    'COIL_CURRENT_COMMAND',
    'COIL_VOLTAGE',
    'COIL_DUTY',
    'STATUS_OK',
    'STATUS_CRASH_BASE',
    'STATUS_CRASH_WORKSPACE',
    'STATUS_NOT_FINITE',
    'STATUS_BAD_INPUT',
]

TORQUE_TRUE = 0
TORQUE_PUBLISHED = 1
KINEMATICS_RIGID = 0
KINEMATICS_PUBLISHED = 1

COIL_IDEAL = 0
COIL_CURRENT_COMMAND = 1
COIL_VOLTAGE = 2
COIL_DUTY = 3

STATUS_OK = 0
STATUS_CRASH_BASE = 1
STATUS_CRASH_WORKSPACE = 2
STATUS_NOT_FINITE = 3
STATUS_BAD_INPUT = 4

GRAVITY = 9.81  # m/s^2, the model's value

_PAIR = LOOP_WORK_ROWS  # first row of the per-pair arrays (z, a, I, Br/rho, Bz, dx, dy)
_RIM = _PAIR + 7  # first row of the per-point arrays (offset 3, tangent 3, point 3, B 3)
#: Rows of the scratch array every kernel takes (``work``).
WORK_ROWS = _RIM + 12

# indices into ``par``
P_RIM_RADIUS, P_SCALE, P_K0, P_MASS, P_IXX, P_IYY, P_IZZ, P_TORQUE, P_KINEMATICS = range(9)


@njit(cache=True, error_model='numpy')
def rotation_matrix(alpha: float, beta: float, gamma: float) -> np.ndarray:
    """R = Rz(gamma) Ry(beta) Rx(alpha), body to world, shape (3, 3).

    Parameters
    ----------
    alpha : float
        Roll angle about x, rad.
    beta : float
        Pitch angle about y, rad.
    gamma : float
        Yaw angle about z, rad.
    """
    ca, sa = math.cos(alpha), math.sin(alpha)
    cb, sb = math.cos(beta), math.sin(beta)
    cg, sg = math.cos(gamma), math.sin(gamma)
    r = np.empty((3, 3))
    r[0, 0] = cg * cb
    r[0, 1] = cg * sb * sa - sg * ca
    r[0, 2] = cg * sb * ca + sg * sa
    r[1, 0] = sg * cb
    r[1, 1] = sg * sb * sa + cg * ca
    r[1, 2] = sg * sb * ca - cg * sa
    r[2, 0] = -sb
    r[2, 1] = cb * sa
    r[2, 2] = cb * ca
    return r


@njit(cache=True)
def euler_to_quaternion(alpha: float, beta: float, gamma: float) -> tuple[float, ...]:
    """Quaternion (x, y, z, w) of ``R = Rz(gamma) Ry(beta) Rx(alpha)`` (angles in rad).

    Parameters
    ----------
    alpha : float
        Roll angle about x, rad.
    beta : float
        Pitch angle about y, rad.
    gamma : float
        Yaw angle about z, rad.
    """
    ca, sa = math.cos(alpha / 2), math.sin(alpha / 2)
    cb, sb = math.cos(beta / 2), math.sin(beta / 2)
    cg, sg = math.cos(gamma / 2), math.sin(gamma / 2)
    return (
        sa * cb * cg - ca * sb * sg,
        ca * sb * cg + sa * cb * sg,
        ca * cb * sg - sa * sb * cg,
        ca * cb * cg + sa * sb * sg,
    )


@njit(cache=True)
def sensor_reading(y, offset, noise, noise_rms, quantization, out):  # pragma: no cover - jitted
    """Write a sensor reading: ``round((y + offset + noise_rms noise) / q) q``, q the LSB.

    The arithmetic of numpy's ``y + offset``, ``+ noise_rms * noise`` and
    ``np.round(r / q) * q`` in that order (round half to even), element by
    element.

    Parameters
    ----------
    y, offset, noise : ndarray, shape (n,)
        True field (T), sensor offsets (T) and standard normal noise.
    noise_rms : float
        Noise, T rms (0: none added).
    quantization : float
        T per LSB (0: none).
    out : ndarray, shape (n,)
        Written: the reading, T.
    """
    for j in range(y.shape[0]):
        r = y[j] + offset[j]
        if noise_rms > 0:
            r = r + noise_rms * noise[j]
        if quantization > 0:
            r = np.round(r / quantization) * quantization
        out[j] = r


@njit(cache=True)
def odometry_fill(x, out):  # pragma: no cover - jitted
    """Write the 13 Odometry numbers of state ``x`` into ``out`` (:func:`odometry_values`).

    Parameters
    ----------
    x : ndarray, shape (12,)
        State: position (m), ZYX Euler angles (rad), world velocity (m/s),
        body rates (rad/s).
    out : ndarray, shape (13,)
        Written: position (3), quaternion x y z w (4), magnet-frame velocity
        (3), body rates (3).
    """
    out[0:3] = x[0:3]
    out[3], out[4], out[5], out[6] = euler_to_quaternion(x[3], x[4], x[5])
    rot = rotation_matrix(x[3], x[4], x[5])
    for i in range(3):  # R^T v: the world velocity in the magnet frame
        out[7 + i] = rot[0, i] * x[6] + rot[1, i] * x[7] + rot[2, i] * x[8]
    out[10:13] = x[9:12]


@njit(cache=True)
def _odometry_state_fill(values, x):  # pragma: no cover - jitted
    """Write the 12-state that the 13 Odometry numbers ``values`` carry into ``x``."""
    qx, qy, qz, qw = values[3], values[4], values[5], values[6]
    alpha = math.atan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy))
    beta = math.asin(max(-1.0, min(1.0, 2 * (qw * qy - qz * qx))))
    gamma = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    x[0:3] = values[0:3]
    x[3], x[4], x[5] = alpha, beta, gamma
    rot = rotation_matrix(alpha, beta, gamma)
    for i in range(3):  # R v: the magnet-frame velocity in the world
        x[6 + i] = rot[i, 0] * values[7] + rot[i, 1] * values[8] + rot[i, 2] * values[9]
    x[9:12] = values[10:13]


@njit(cache=True)
def _odometry_round_trip(x, values, out):  # pragma: no cover - jitted
    odometry_fill(x, values)
    _odometry_state_fill(values, out)


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
    out = np.empty(13)
    odometry_fill(np.ascontiguousarray(x, dtype=float), out)
    return out


def odometry_state_values(values) -> np.ndarray:
    """Return the 12-state that the 13 Odometry numbers of :func:`odometry_values` carry.

    The inverse of :func:`odometry_values` up to rounding: ZYX Euler angles
    from the quaternion, world velocity from the magnet-frame one.

    Parameters
    ----------
    values : sequence of float, length 13
        Position (3), quaternion x y z w (4), magnet-frame velocity (3), body rates (3).

    Returns
    -------
    ndarray, shape (12,)
        Position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    """
    x = np.empty(12)
    _odometry_state_fill(np.ascontiguousarray(values, dtype=float), x)
    return x


def odometry_round_trip(x: np.ndarray) -> np.ndarray:
    """Return state ``x`` as a node reads it back from its Odometry (rounding included).

    A consumer of ``maglev/state/estimate`` gets the state through the
    quaternion and the magnet-frame velocity, which round the Euler angles and
    the world velocity by about 1e-16 relative; the ROS-free closed loop passes
    its estimate through this so that it steps exactly as the nodes do (one
    compiled call: the same arithmetic as :func:`odometry_values` then
    :func:`odometry_state_values`).

    Parameters
    ----------
    x : ndarray, shape (12,)
        Position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.

    Returns
    -------
    ndarray, shape (12,)
    """
    values, out = np.empty(13), np.empty(12)
    _odometry_round_trip(np.ascontiguousarray(x, dtype=float), values, out)
    return out


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def base_field_points(px, py, pz, u, src, coil, work, out):
    """Field of all base loops at the points (px, py, pz) (n,), T.

    Writes Bx, By, Bz to ``out`` rows 0-2 (shape (3, >= n)). Builds the
    (point, loop) pairs in ``work`` and evaluates them in one vectorised batch.

    Parameters
    ----------
    px : ndarray, shape (n,)
        x of the points, m.
    py : ndarray, shape (n,)
        y of the points, m.
    pz : ndarray, shape (n,)
        z of the points, m.
    u : ndarray, shape (n_s,)
        Solenoid currents, A.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    out : ndarray, shape (3, >= n)
        Output: Bx, By, Bz in rows 0-2, T.
    """
    n = px.shape[0]
    n_src = src.shape[0]
    if n_src == 0:
        for i in range(n):
            out[0, i] = 0.0
            out[1, i] = 0.0
            out[2, i] = 0.0
        return
    total = n * n_src
    zz = work[_PAIR, :total]
    aa = work[_PAIR + 1, :total]
    cur = work[_PAIR + 2, :total]
    br = work[_PAIR + 3, :total]
    bz = work[_PAIR + 4, :total]
    ddx = work[_PAIR + 5, :total]
    ddy = work[_PAIR + 6, :total]
    # pairs in source-major order: inner loops run over points and vectorise
    for j in range(n_src):
        current = src[j, 4]
        if coil[j] >= 0:
            current += src[j, 5] * u[coil[j]]
        cx, cy, cz, radius = src[j, 0], src[j, 1], src[j, 2], src[j, 3]
        base = j * n
        for i in range(n):
            ddx[base + i] = px[i] - cx
            ddy[base + i] = py[i] - cy
            zz[base + i] = pz[i] - cz
            aa[base + i] = radius
            cur[base + i] = current
    loop_batch(ddx, ddy, zz, aa, cur, br, bz, work)
    for k in range(total):
        ddx[k] *= br[k]  # Bx contribution
        ddy[k] *= br[k]  # By contribution
    # Pairwise (tree) sum over the sources in their listed order. Besides being
    # accurate, it keeps mirror images of the base (x+/x-, y+/y- neighbours in
    # the list) in sibling subtrees, so a centred magnet feels exactly zero
    # horizontal force in floating point and stays centred (an unstable mode
    # would otherwise amplify round-off into visible drift).
    sum_x = _tree_sum(ddx, zz, n, n_src)  # the pair rows z, a, I are free again
    sum_y = _tree_sum(ddy, aa, n, n_src)
    sum_z = _tree_sum(bz, cur, n, n_src)
    for i in range(n):
        out[0, i] = sum_x[i]
        out[1, i] = sum_y[i]
        out[2, i] = sum_z[i]


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _tree_sum(values, scratch, n, n_blocks):
    """Pairwise sum of ``n_blocks`` consecutive blocks of length ``n``.

    Ping-pongs between ``values`` and ``scratch`` (one read-read-write stream
    per loop, so it vectorises); returns the array whose first ``n`` entries
    hold the sum.
    """
    src = values
    dst = scratch
    width = n_blocks
    while width > 1:
        half = width // 2
        for j in range(half):
            d = j * n
            a = 2 * j * n
            b = a + n
            for i in range(n):
                dst[d + i] = src[a + i] + src[b + i]
        if width % 2:
            d = half * n
            last = (width - 1) * n
            for i in range(n):
                dst[d + i] = src[last + i]
            half += 1
        width = half
        src, dst = dst, src
    return src


@njit(cache=True)
def loops_field(points, u, src, coil):
    """Field of the base loops at ``points`` (n, 3), T, shape (n, 3).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        World points, m.
    u : ndarray, shape (n_s,)
        Solenoid currents, A.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    """
    n = points.shape[0]
    out = np.zeros((3, n))
    if n > 0 and src.shape[0] > 0:
        work = np.empty((WORK_ROWS, n * src.shape[0]))
        base_field_points(
            points[:, 0].copy(), points[:, 1].copy(), points[:, 2].copy(), u, src, coil, work, out
        )
    return out.T.copy()


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def rim_force_torque(x, u, src, coil, rim, par, work, r):
    """Force and torque on the magnet's rim current (fast model), world frame.

    ``r`` is the magnet's rotation matrix (3, 3) for the angles in ``x``.
    Returns an array of shape (6,): (Fx, Fy, Fz) in N, (tau_x, tau_y, tau_z) in N m
    about the magnet's centre.

    Parameters
    ----------
    x : ndarray, shape (12,)
        State: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    u : ndarray, shape (n_s,)
        Solenoid currents, A.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    rim : ndarray, shape (2, n)
        cos and sin of the rim angles of the magnet.
    par : ndarray, shape (9,)
        Model parameters (see the module docstring).
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    r : ndarray, shape (3, 3)
        Rotation matrix of the angles in ``x``, body to world.
    """
    n = rim.shape[1]
    rim_radius = par[P_RIM_RADIUS]
    k0 = par[P_K0]
    off = work[_RIM : _RIM + 3]
    tan = work[_RIM + 3 : _RIM + 6]
    pts = work[_RIM + 6 : _RIM + 9]
    field = work[_RIM + 9 : _RIM + 12]
    for i in range(n):
        c = rim[0, i]
        s = rim[1, i]
        for a in range(3):
            # rim offset d = R [R_rim c, R_rim s, 0], tangent t = R [-s, c, 0]
            off[a, i] = rim_radius * (r[a, 0] * c + r[a, 1] * s)
            tan[a, i] = -r[a, 0] * s + r[a, 1] * c
            pts[a, i] = x[a] + off[a, i]
    base_field_points(pts[0, :n], pts[1, :n], pts[2, :n], u, src, coil, work, field)
    contrib = work[_PAIR : _PAIR + 6]  # per-point wrench; the pair rows are free again
    nzx, nzy, nzz = r[0, 2], r[1, 2], r[2, 2]
    published = par[P_TORQUE] != TORQUE_TRUE
    for i in range(n):
        bx, by, bz = field[0, i], field[1, i], field[2, i]
        tx, ty, tz = tan[0, i], tan[1, i], tan[2, i]
        fx = k0 * (ty * bz - tz * by)
        fy = k0 * (tz * bx - tx * bz)
        fz = k0 * (tx * by - ty * bx)
        contrib[0, i] = fx
        contrib[1, i] = fy
        contrib[2, i] = fz
        if published:  # the reference code's K0 n_z x B (a force; kept as an option)
            contrib[3, i] = k0 * (nzy * bz - nzz * by)
            contrib[4, i] = k0 * (nzz * bx - nzx * bz)
            contrib[5, i] = k0 * (nzx * by - nzy * bx)
        else:  # moment of the rim forces
            dx, dy, dz = off[0, i], off[1, i], off[2, i]
            contrib[3, i] = dy * fz - dz * fy
            contrib[4, i] = dz * fx - dx * fz
            contrib[5, i] = dx * fy - dy * fx
    out = np.zeros(6)
    if n % 4 == 0:
        # Sum each component over mirror pairs of rim points: the x-mirror
        # (theta -> pi - theta) for the x-odd Fx, tau_y, tau_z, the y-mirror
        # (theta -> -theta) for the y-odd Fy, tau_x. A centred, level magnet's
        # odd components then cancel exactly (see base_field_points).
        half = n // 2
        for i in range(n):
            mx = half - i if i <= half else n + half - i  # (n/2 - i) mod n, no division
            my = n - i if i > 0 else 0  # (-i) mod n
            out[0] += contrib[0, i] + contrib[0, mx]
            out[1] += contrib[1, i] + contrib[1, my]
            out[2] += contrib[2, i] + contrib[2, mx]
            out[3] += contrib[3, i] + contrib[3, my]
            out[4] += contrib[4, i] + contrib[4, mx]
            out[5] += contrib[5, i] + contrib[5, mx]
        scale = 0.5 * par[P_SCALE]
    else:
        for i in range(n):
            for k in range(6):
                out[k] += contrib[k, i]
        scale = par[P_SCALE]
    for k in range(6):
        out[k] *= scale
    return out


@njit(cache=True, error_model='numpy')
def rigid_body_rates(x, wrench, mass, inertia, kinematics, r):
    """Time derivative of the 12-state from the magnetic wrench (world frame).

    State: position (3) m, Euler angles (alpha, beta, gamma) rad, linear
    velocity (3) m/s (world), angular velocity (3) rad/s (body frame).
    ``kinematics``: KINEMATICS_RIGID (ZYX Euler kinematics, body-frame torque)
    or KINEMATICS_PUBLISHED (Euler rates = w, world torque). ``r``: the rotation
    matrix (3, 3) of the angles in ``x``.

    Parameters
    ----------
    x : ndarray, shape (12,)
        State: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    wrench : ndarray, shape (6,)
        Force (N) and torque (N m) on the magnet, world frame.
    mass : float
        Magnet mass, kg.
    inertia : ndarray, shape (3,)
        Principal moments of inertia, kg m^2.
    kinematics : int
        KINEMATICS_RIGID or KINEMATICS_PUBLISHED.
    r : ndarray, shape (3, 3)
        Rotation matrix of the angles in ``x``, body to world.
    """
    dx = np.empty(12)
    dx[0] = x[6]
    dx[1] = x[7]
    dx[2] = x[8]
    dx[6] = wrench[0] / mass
    dx[7] = wrench[1] / mass
    dx[8] = wrench[2] / mass - GRAVITY
    wx, wy, wz = x[9], x[10], x[11]
    ixx, iyy, izz = inertia[0], inertia[1], inertia[2]
    if kinematics == KINEMATICS_RIGID:
        # body-frame torque R^T tau
        tx = r[0, 0] * wrench[3] + r[1, 0] * wrench[4] + r[2, 0] * wrench[5]
        ty = r[0, 1] * wrench[3] + r[1, 1] * wrench[4] + r[2, 1] * wrench[5]
        tz = r[0, 2] * wrench[3] + r[1, 2] * wrench[4] + r[2, 2] * wrench[5]
        ca, sa = math.cos(x[3]), math.sin(x[3])
        cb = math.cos(x[4])
        tb = math.tan(x[4])
        dx[3] = wx + (wy * sa + wz * ca) * tb
        dx[4] = wy * ca - wz * sa
        dx[5] = (wy * sa + wz * ca) / cb
    else:
        tx, ty, tz = wrench[3], wrench[4], wrench[5]
        dx[3] = wx
        dx[4] = wy
        dx[5] = wz
    # Euler's equations I dw/dt = tau - w x (I w), written with inertia differences
    # so that an axisymmetric magnet (Ixx == Iyy) keeps its spin rate exactly
    dx[9] = (tx - (izz - iyy) * wy * wz) / ixx
    dx[10] = (ty - (ixx - izz) * wz * wx) / iyy
    dx[11] = (tz - (iyy - ixx) * wx * wy) / izz
    return dx


@njit(cache=True, error_model='numpy')
def fast_dynamics(x, u, src, coil, rim, par, work):
    """f(x, u) of the fast model, shape (12,).

    Parameters
    ----------
    x : ndarray, shape (12,)
        State: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    u : ndarray, shape (n_s,)
        Solenoid currents, A.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    rim : ndarray, shape (2, n)
        cos and sin of the rim angles of the magnet.
    par : ndarray, shape (9,)
        Model parameters (see the module docstring).
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    """
    r = rotation_matrix(x[3], x[4], x[5])
    wrench = rim_force_torque(x, u, src, coil, rim, par, work, r)
    return rigid_body_rates(
        x, wrench, par[P_MASS], par[P_IXX : P_IZZ + 1], int(par[P_KINEMATICS]), r
    )


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def fast_measurement(x, u, src, coil, sens, mag, work):
    """h(x, u) of the fast model: stacked sensor readings, T, shape (3 k,).

    Parameters
    ----------
    x : ndarray, shape (12,)
        State: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    u : ndarray, shape (n_s,)
        Solenoid currents, A.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    sens : ndarray, shape (k, 18)
        Per sensor: position, mounting rotation, gain, offset (module docstring).
    mag : ndarray, shape (2,)
        The magnet's own loop radius (m) and current (A), for the sensor model.
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    """
    r = rotation_matrix(x[3], x[4], x[5])
    n = sens.shape[0]
    base = np.zeros((3, n))
    if src.shape[0] > 0:
        base_field_points(
            sens[:, 0].copy(), sens[:, 1].copy(), sens[:, 2].copy(), u, src, coil, work, base
        )
    # the levitating magnet: a loop in its own frame, evaluated at R^T (s - p)
    local = np.empty((3, n))
    for k in range(n):
        wx = sens[k, 0] - x[0]
        wy = sens[k, 1] - x[1]
        wz = sens[k, 2] - x[2]
        for a in range(3):
            local[a, k] = r[0, a] * wx + r[1, a] * wy + r[2, a] * wz
    own_src = np.zeros((1, 6))
    own_src[0, 3] = mag[0]
    own_src[0, 4] = mag[1]
    own = np.empty((3, n))
    base_field_points(local[0], local[1], local[2], u, own_src, np.full(1, -1), work, own)
    y = np.empty(3 * n)
    total = np.empty(3)
    for k in range(n):
        for a in range(3):
            total[a] = base[a, k] + r[a, 0] * own[0, k] + r[a, 1] * own[1, k] + r[a, 2] * own[2, k]
        for a in range(3):
            # reading = gain * (R_mount^T B) + offset
            reading = (
                sens[k, 3 + a] * total[0] + sens[k, 6 + a] * total[1] + sens[k, 9 + a] * total[2]
            )
            y[3 * k + a] = sens[k, 12 + a] * reading + sens[k, 15 + a]
    return y


@njit(cache=True, error_model='numpy')
def crash_status(x, base_top, magnet_radius, half_thickness, lower, upper):
    """Crash check of a state: STATUS_OK, _CRASH_BASE, _CRASH_WORKSPACE or _NOT_FINITE.

    The lowest point of the (tilted) disc must stay above ``base_top`` (m) and
    the centre inside the box [lower, upper] (m).

    Parameters
    ----------
    x : ndarray, shape (12,)
        State: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    base_top : float
        Height of the tops of the base components, m.
    magnet_radius : float
        Magnet radius, m.
    half_thickness : float
        Half the magnet thickness, m.
    lower : ndarray, shape (3,)
        Lower corner of the workspace box, m.
    upper : ndarray, shape (3,)
        Upper corner of the workspace box, m.
    """
    for k in range(x.shape[0]):
        if not math.isfinite(x[k]):
            return STATUS_NOT_FINITE
    for k in range(3):
        if x[k] < lower[k] or x[k] > upper[k]:
            return STATUS_CRASH_WORKSPACE
    nz = math.cos(x[4]) * math.cos(x[3])  # R[2, 2]: vertical part of the disc axis
    lowest = x[2] - magnet_radius * math.sqrt(max(0.0, 1.0 - nz * nz)) - half_thickness * abs(nz)
    if lowest <= base_top:
        return STATUS_CRASH_BASE
    return STATUS_OK


@njit(cache=True, error_model='numpy')
def coil_voltages(drive, coil_mode, coil_r, v_supply):
    """Coil voltages, V, for the drive signal (see :func:`rk4_sample`), clipped at the supply.

    Parameters
    ----------
    drive : ndarray, shape (n_s,)
        Drive signal per coil, its unit set by ``coil_mode``.
    coil_mode : int
        COIL_IDEAL, COIL_CURRENT_COMMAND, COIL_VOLTAGE or COIL_DUTY.
    coil_r : float
        Coil resistance, ohm.
    v_supply : float
        Supply voltage, V.
    """
    v = np.empty(drive.shape[0])
    for j in range(drive.shape[0]):
        if coil_mode == COIL_CURRENT_COMMAND:
            volts = coil_r * drive[j]
        elif coil_mode == COIL_VOLTAGE:
            volts = drive[j]
        else:
            volts = drive[j] * v_supply
        v[j] = min(max(volts, -v_supply), v_supply)
    return v


@njit(cache=True, error_model='numpy')
def extended_rates(xe, drive, coil, v, coil_mode, coil_r, coil_l, src, rim, par, work):
    """Rates of the state; with coil dynamics, of [12-state, coil currents].

    Parameters
    ----------
    xe : ndarray, shape (n_x,)
        Extended state: the 12 mechanical states, then the coil currents (A) with coil dynamics.
    drive : ndarray, shape (n_s,)
        Drive signal per coil, its unit set by ``coil_mode``.
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    v : ndarray, shape (n_s,)
        Coil voltages, V (scratch, overwritten).
    coil_mode : int
        COIL_IDEAL, COIL_CURRENT_COMMAND, COIL_VOLTAGE or COIL_DUTY.
    coil_r : float
        Coil resistance, ohm.
    coil_l : float
        Coil inductance, H.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    rim : ndarray, shape (2, n)
        cos and sin of the rim angles of the magnet.
    par : ndarray, shape (9,)
        Model parameters (see the module docstring).
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    """
    if coil_mode == COIL_IDEAL:
        return fast_dynamics(xe, drive, src, coil, rim, par, work)
    n_coils = v.shape[0]
    out = np.empty(xe.shape[0])
    i_coil = xe[12 : 12 + n_coils].copy()
    out[:12] = fast_dynamics(xe[:12].copy(), i_coil, src, coil, rim, par, work)
    for j in range(n_coils):
        out[12 + j] = (v[j] - coil_r * i_coil[j]) / coil_l
    return out


@njit(cache=True, error_model='numpy')
def rk4_sample(xe, drive, dt, substeps, coil_mode, electrical, src, coil, rim, par, work):
    """Advance the state by one sample of length ``dt`` (s) with RK4 sub-steps.

    ``coil_mode`` COIL_IDEAL: ``drive`` are the coil currents, A (ideal current
    source; the state has 12 entries). COIL_CURRENT_COMMAND: ``drive`` are
    commanded currents, A, applied as the voltage ``R i_cmd`` clipped at the
    supply (what the board does); COIL_VOLTAGE: volts (clipped); COIL_DUTY: PWM
    duties in [-1, 1] (voltage = duty * supply). With coil dynamics the state
    carries the coil currents after the 12 mechanical states, integrated with
    ``L di/dt = V - R i``. ``electrical`` = (R ohm, L H, supply V). The drive
    is held constant over the sample (zero-order hold).

    Parameters
    ----------
    xe : ndarray, shape (n_x,)
        Extended state: the 12 mechanical states, then the coil currents (A) with coil dynamics.
    drive : ndarray, shape (n_s,)
        Drive signal per coil, its unit set by ``coil_mode``.
    dt : float
        Sample period, s.
    substeps : int
        RK4 steps per sample.
    coil_mode : int
        COIL_IDEAL, COIL_CURRENT_COMMAND, COIL_VOLTAGE or COIL_DUTY.
    electrical : ndarray, shape (3,)
        (R ohm, L H, supply V).
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    rim : ndarray, shape (2, n)
        cos and sin of the rim angles of the magnet.
    par : ndarray, shape (9,)
        Model parameters (see the module docstring).
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    """
    h = dt / substeps
    coil_r = electrical[0]
    coil_l = electrical[1]
    v = coil_voltages(drive, coil_mode, coil_r, electrical[2])
    n_x = xe.shape[0]
    x = xe.copy()
    stage = np.empty(n_x)
    acc = np.empty(n_x)
    for _ in range(substeps):
        k = extended_rates(x, drive, coil, v, coil_mode, coil_r, coil_l, src, rim, par, work)
        for i in range(n_x):
            acc[i] = k[i]
            stage[i] = x[i] + 0.5 * h * k[i]
        k = extended_rates(stage, drive, coil, v, coil_mode, coil_r, coil_l, src, rim, par, work)
        for i in range(n_x):
            acc[i] += 2.0 * k[i]
            stage[i] = x[i] + 0.5 * h * k[i]
        k = extended_rates(stage, drive, coil, v, coil_mode, coil_r, coil_l, src, rim, par, work)
        for i in range(n_x):
            acc[i] += 2.0 * k[i]
            stage[i] = x[i] + h * k[i]
        k = extended_rates(stage, drive, coil, v, coil_mode, coil_r, coil_l, src, rim, par, work)
        for i in range(n_x):
            x[i] += (h / 6.0) * (acc[i] + k[i])
    return x


@njit(cache=True, error_model='numpy')
def coil_step(xe, drive, dt, coil_mode, electrical):
    """Advance only the coil currents by one sample (exact first-order solution).

    Used when the magnet is held fixed or absent: the mechanical state is frozen.

    Parameters
    ----------
    xe : ndarray, shape (n_x,)
        Extended state: the 12 mechanical states, then the coil currents (A) with coil dynamics.
    drive : ndarray, shape (n_s,)
        Drive signal per coil, its unit set by ``coil_mode``.
    dt : float
        Sample period, s.
    coil_mode : int
        COIL_IDEAL, COIL_CURRENT_COMMAND, COIL_VOLTAGE or COIL_DUTY.
    electrical : ndarray, shape (3,)
        (R ohm, L H, supply V).
    """
    new = xe.copy()
    if coil_mode == COIL_IDEAL:
        return new
    coil_r = electrical[0]
    v = coil_voltages(drive, coil_mode, coil_r, electrical[2])
    decay = math.exp(-dt * coil_r / electrical[1])
    for j in range(v.shape[0]):
        target = v[j] / coil_r
        new[12 + j] = target + (xe[12 + j] - target) * decay
    return new


# indices into the simulator configuration ``cfg`` (float array, see :func:`simulator_config`)
(
    C_DT,
    C_SUBSTEPS,
    C_COIL_MODE,
    C_CHECK,
    C_FROZEN,
    C_R,
    C_L,
    C_SUPPLY,
    C_BASE_TOP,
    C_MAGNET_RADIUS,
    C_HALF_THICKNESS,
    C_LOWER,
    C_UPPER,
) = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 14)
CONFIG_SIZE = 17


def simulator_config(dt, substeps, coil_mode, check, frozen, electrical, crash) -> np.ndarray:
    """Pack the simulator's settings into one float array (fewer arguments per call).

    ``electrical`` = (R ohm, L H, supply V); ``crash`` = (base top m, magnet radius m,
    half thickness m, lower xyz m, upper xyz m).

    Parameters
    ----------
    dt : float
        Sample period, s.
    substeps : int
        RK4 steps per sample.
    coil_mode : int
        COIL_IDEAL, COIL_CURRENT_COMMAND, COIL_VOLTAGE or COIL_DUTY.
    check : bool
        Check for crashes.
    frozen : bool
        Magnet held fixed or absent: only the coil currents advance.
    electrical : ndarray, shape (3,)
        (R ohm, L H, supply V).
    crash : ndarray
        (base top m, magnet radius m, half thickness m, lower xyz m, upper xyz m).
    """
    cfg = np.empty(CONFIG_SIZE)
    cfg[C_DT] = dt
    cfg[C_SUBSTEPS] = substeps
    cfg[C_COIL_MODE] = coil_mode
    cfg[C_CHECK] = 1.0 if check else 0.0
    cfg[C_FROZEN] = 1.0 if frozen else 0.0
    cfg[C_R : C_SUPPLY + 1] = electrical
    cfg[C_BASE_TOP:] = crash
    return cfg


@njit(cache=True, error_model='numpy')
def sample_step(xe, drive, cfg, src, coil, rim, par, work, sens, mag):
    """One simulator sample: RK4 step, crash check and the true sensor reading.

    ``cfg`` is :func:`simulator_config`'s array. Returns (new extended state,
    status, reading (3 k,)). On a crash the state is the attempted one and the
    reading is taken at the previous state; a non-finite drive returns
    STATUS_BAD_INPUT and leaves the state alone. A frozen simulator (fixed or
    absent magnet) only advances the coil currents.

    Parameters
    ----------
    xe : ndarray, shape (n_x,)
        Extended state: the 12 mechanical states, then the coil currents (A) with coil dynamics.
    drive : ndarray, shape (n_s,)
        Drive signal per coil, its unit set by ``coil_mode``.
    cfg : ndarray
        The settings of :func:`simulator_config`.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    rim : ndarray, shape (2, n)
        cos and sin of the rim angles of the magnet.
    par : ndarray, shape (9,)
        Model parameters (see the module docstring).
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    sens : ndarray, shape (k, 18)
        Per sensor: position, mounting rotation, gain, offset (module docstring).
    mag : ndarray, shape (2,)
        The magnet's own loop radius (m) and current (A), for the sensor model.
    """
    for j in range(drive.shape[0]):
        if not math.isfinite(drive[j]):
            return xe.copy(), STATUS_BAD_INPUT, np.zeros(3 * sens.shape[0])
    dt = cfg[C_DT]
    coil_mode = int(cfg[C_COIL_MODE])
    electrical = cfg[C_R : C_SUPPLY + 1]
    if cfg[C_FROZEN] != 0.0:
        new = coil_step(xe, drive, dt, coil_mode, electrical)
        currents = new[12:] if coil_mode != COIL_IDEAL else drive
        y = fast_measurement(new[:12].copy(), currents.copy(), src, coil, sens, mag, work)
        return new, STATUS_OK, y
    new = rk4_sample(
        xe, drive, dt, int(cfg[C_SUBSTEPS]), coil_mode, electrical, src, coil, rim, par, work
    )
    if cfg[C_CHECK] != 0.0:
        status = crash_status(
            new[:12],
            cfg[C_BASE_TOP],
            cfg[C_MAGNET_RADIUS],
            cfg[C_HALF_THICKNESS],
            cfg[C_LOWER : C_LOWER + 3],
            cfg[C_UPPER : C_UPPER + 3],
        )
    else:
        status = STATUS_OK
        for k in range(new.shape[0]):
            if not math.isfinite(new[k]):
                status = STATUS_NOT_FINITE
    seen = new if status == STATUS_OK else xe
    currents = seen[12:] if coil_mode != COIL_IDEAL else drive
    y = fast_measurement(seen[:12].copy(), currents.copy(), src, coil, sens, mag, work)
    return new, status, y


@njit(cache=True, error_model='numpy')
def rk4_run(x0, drives, cfg, src, coil, rim, par, work, sens, mag):
    """Integrate over ``drives.shape[0]`` samples; stop at the first crash.

    ``cfg`` is :func:`simulator_config`'s array. Returns (states (K + 1, n_x),
    true readings (K + 1, 3 k), samples done K, status, attempted state at the
    crash).

    Parameters
    ----------
    x0 : ndarray, shape (n_x,)
        Initial extended state.
    drives : ndarray, shape (K, n_s)
        Drive signal of each sample.
    cfg : ndarray
        The settings of :func:`simulator_config`.
    src : ndarray, shape (S, 6)
        Packed loop sources of the base (see the module docstring).
    coil : ndarray of int64, shape (S,)
        Input feeding each loop (-1: none).
    rim : ndarray, shape (2, n)
        cos and sin of the rim angles of the magnet.
    par : ndarray, shape (9,)
        Model parameters (see the module docstring).
    work : ndarray, shape (WORK_ROWS, >= n S)
        Scratch space, overwritten.
    sens : ndarray, shape (k, 18)
        Per sensor: position, mounting rotation, gain, offset (module docstring).
    mag : ndarray, shape (2,)
        The magnet's own loop radius (m) and current (A), for the sensor model.
    """
    n = drives.shape[0]
    n_y = 3 * sens.shape[0]
    states = np.empty((n + 1, x0.shape[0]))
    outputs = np.empty((n + 1, n_y))
    states[0] = x0
    if int(cfg[C_COIL_MODE]) == COIL_IDEAL:
        first = np.zeros(drives.shape[1])
    else:
        first = x0[12:].copy()
    outputs[0] = fast_measurement(x0[:12].copy(), first, src, coil, sens, mag, work)
    x = x0.copy()
    for k in range(n):
        new, status, y = sample_step(x, drives[k], cfg, src, coil, rim, par, work, sens, mag)
        if status != STATUS_OK:
            return states[: k + 1], outputs[: k + 1], k, status, new
        x = new
        states[k + 1] = x
        outputs[k + 1] = y
    return states, outputs, n, STATUS_OK, x
