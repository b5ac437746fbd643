"""Compiled (numba) Kalman-filter steps shared by the KF and the EKF.

The equations are filterpy's (``KalmanFilter.predict`` / ``update``): predict
``x = F x + B u``, ``P = F P F' + Q``; update with ``S = H P H' + R``,
``K = P H' S^-1`` and the Joseph form ``P = (I - K H) P (I - K H)' + K R K'``,
which keeps P symmetric positive definite; P is symmetrised after each step.
One compiled call per step keeps a 5 kHz filter at a few microseconds.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..physics import kernels as phys

__all__ = [
    'spd_inverse',
    'kf_predict',
    'gated_update',
    'ekf_transition',
    'ekf_predict',
    'ekf_measure',
    'embed_state',
    'freeze_check',
    'odometry_covariances',
    'estimate_values',
]


@njit(cache=True)
def _mm(a, b):  # pragma: no cover - jitted
    """Return a @ b by plain loops (no BLAS call: faster for these small matrices)."""
    n, k = a.shape
    m = b.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for p in range(k):
            v = a[i, p]
            if v != 0.0:
                for j in range(m):
                    out[i, j] += v * b[p, j]
    return out


@njit(cache=True)
def _mmt(a, b):  # pragma: no cover - jitted
    """Return a @ b.T by plain loops."""
    n, k = a.shape
    m = b.shape[0]
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for p in range(k):
                acc += a[i, p] * b[j, p]
            out[i, j] = acc
    return out


@njit(cache=True)
def _mv(a, v):  # pragma: no cover - jitted
    n, k = a.shape
    out = np.zeros(n)
    for i in range(n):
        acc = 0.0
        for p in range(k):
            acc += a[i, p] * v[p]
        out[i] = acc
    return out


@njit(cache=True)
def spd_inverse(s):  # pragma: no cover - jitted
    """Inverse of a small symmetric positive definite matrix (Cholesky), symmetric.

    Parameters
    ----------
    s : ndarray, shape (k, k)
        Symmetric positive definite.
    """
    n = s.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        d = s[j, j]
        for p in range(j):
            d -= L[j, p] * L[j, p]
        if not d > 0.0:
            return np.linalg.inv(s)  # not SPD to round-off: fall back to LU
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, n):
            acc = s[i, j]
            for p in range(j):
                acc -= L[i, p] * L[j, p]
            L[i, j] = acc / L[j, j]
    # inverse of L (lower triangular), then inv(S) = inv(L)' inv(L)
    li = np.zeros((n, n))
    for j in range(n):
        li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            acc = 0.0
            for p in range(j, i):
                acc -= L[i, p] * li[p, j]
            li[i, j] = acc / L[i, i]
    out = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            acc = 0.0
            for p in range(j, n):
                acc += li[p, i] * li[p, j]
            out[i, j] = acc
            out[j, i] = acc
    return out


@njit(cache=True)
def _symmetrise(p):  # pragma: no cover - jitted
    n = p.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            v = 0.5 * (p[i, j] + p[j, i])
            p[i, j] = v
            p[j, i] = v
    return p


@njit(cache=True)
def kf_predict(x, P, F, B, u, Q):  # pragma: no cover - jitted
    """Linear prediction: returns (F x + B u, F P F' + Q), P symmetrised.

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    F : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    u : ndarray, shape (m,)
    Q : ndarray, shape (n, n)
    """
    xn = _mv(F, x) + _mv(B, u)
    Pn = _mmt(_mm(F, P), F) + Q
    return xn, _symmetrise(Pn)


@njit(cache=True)
def gate_sensors(S, nu, available, gate):  # pragma: no cover - jitted
    """Chi-square gate per 3-axis sensor: which readings an update takes.

    Parameters
    ----------
    S : ndarray, shape (3 k, 3 k)
        Innovation covariance, T^2.
    nu : ndarray, shape (3 k,)
        Innovation, T.
    available : ndarray of bool, shape (k,)
        Sensors with a reading this sample.
    gate : float
        NIS threshold per sensor (chi-square, 3 dof).

    Returns
    -------
    accepted : ndarray of bool, shape (k,)
    nis_sensor : ndarray, shape (k,)
        Each available sensor's NIS against its own 3x3 block of S (NaN if missing).
    index : ndarray of int, shape (3 accepted,)
        Rows of the accepted readings.
    """
    k = available.shape[0]
    accepted = np.zeros(k, dtype=np.bool_)
    nis_sensor = np.full(k, np.nan)
    rows = 0
    for s in range(k):
        if not available[s]:
            continue
        block = S[3 * s : 3 * s + 3, 3 * s : 3 * s + 3].copy()
        v = nu[3 * s : 3 * s + 3].copy()
        value = v @ _mv(spd_inverse(block), v)
        nis_sensor[s] = value
        if value <= gate:
            accepted[s] = True
            rows += 3
    index = np.empty(rows, dtype=np.int64)
    j = 0
    for s in range(k):
        if accepted[s]:
            for a in range(3):
                index[j] = 3 * s + a
                j += 1
    return accepted, nis_sensor, index


@njit(cache=True)
def gated_update(x, P, H, r_diag, nu, available, gate):  # pragma: no cover - jitted
    """Kalman update with a chi-square gate per 3-axis sensor (Joseph form).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Prior state.
    P : ndarray, shape (n, n)
        Prior covariance.
    H : ndarray, shape (3 k, n)
        Measurement matrix (Jacobian).
    r_diag : ndarray, shape (3 k,)
        Measurement variances, T^2.
    nu : ndarray, shape (3 k,)
        Innovation (reading minus predicted reading), T.
    available : ndarray of bool, shape (k,)
        Sensors with a reading this sample (not missing, not frozen).
    gate : float
        NIS threshold per sensor (chi-square, 3 dof).

    Returns
    -------
    x, P : ndarray
        Posterior (the prior when no sensor is accepted).
    accepted : ndarray of bool, shape (k,)
    nis_sensor : ndarray, shape (k,)
        Each available sensor's NIS against its own 3x3 block of S (NaN if missing).
    nis : float
        NIS of the accepted readings together (0 when none).
    dof : int
        Rows used (3 per accepted sensor).
    """
    n = x.shape[0]
    PHT = _mmt(P, H)
    S = _mm(H, PHT)
    for i in range(S.shape[0]):
        S[i, i] += r_diag[i]
    accepted, nis_sensor, index = gate_sensors(S, nu, available, gate)
    rows = index.shape[0]
    if rows == 0:
        return x.copy(), P.copy(), accepted, nis_sensor, 0.0, 0
    Hs = np.empty((rows, n))
    Ss = np.empty((rows, rows))
    PHTs = np.empty((n, rows))
    vs = np.empty(rows)
    rs = np.empty(rows)
    for a in range(rows):
        ia = index[a]
        Hs[a] = H[ia]
        PHTs[:, a] = PHT[:, ia]
        vs[a] = nu[ia]
        rs[a] = r_diag[ia]
        for b in range(rows):
            Ss[a, b] = S[ia, index[b]]
    SI = spd_inverse(Ss)
    K = _mm(PHTs, SI)
    xn = x + _mv(K, vs)
    IKH = -_mm(K, Hs)
    for i in range(n):
        IKH[i, i] += 1.0
    KR = K * rs  # K R (R diagonal)
    Pn = _mmt(_mm(IKH, P), IKH) + _mmt(KR, K)
    nis = vs @ _mv(SI, vs)
    return xn, _symmetrise(Pn), accepted, nis_sensor, nis, rows


@njit(cache=True)
def embed_state(dx, x_eq, reduced):  # pragma: no cover - jitted
    """Full 12-state from a reduced deviation: ``x_eq`` plus ``dx`` at ``reduced``.

    Parameters
    ----------
    dx : ndarray, shape (10,)
        Reduced deviation.
    x_eq : ndarray, shape (12,)
        Equilibrium.
    reduced : ndarray of int, shape (10,)
        Indices of the reduced states in the 12-state.
    """
    x = x_eq.copy()
    for i in range(reduced.shape[0]):
        x[reduced[i]] += dx[i]
    return x


@njit(cache=True)
def ekf_transition(
    dx, u, x_eq, reduced, dt, step, src, coil, rim, par, work
):  # pragma: no cover - jitted
    """Propagated mean and transition matrix of the nonlinear model over one sample.

    The mean: one RK4 step of f with the current ``u`` held (ZOH). The
    transition: ``exp(A dt)`` (third-order series; ``|A| dt < 0.05`` at 5 kHz)
    of the reduced Jacobian A, by central differences of f (``step``). States
    beyond the 10 reduced ones (sensor biases) are random walks.

    Parameters
    ----------
    dx : ndarray, shape (n,)
        Reduced deviation (+ biases).
    u : ndarray, shape (m,)
        Coil currents, A.
    x_eq : ndarray, shape (12,)
    reduced : ndarray of int, shape (10,)
    dt : float
        s.
    step : float
        Finite-difference step.
    src, coil, rim, par, work : ndarray
        The fast model's packed arguments (``MaggyModel.fast_arguments``).

    Returns
    -------
    x_next : ndarray, shape (n,)
    F : ndarray, shape (n, n)
    """
    n_r = reduced.shape[0]
    n = dx.shape[0]
    x12 = embed_state(dx[:n_r], x_eq, reduced)
    electrical = np.ones(3)
    new = phys.rk4_sample(x12, u, dt, 1, phys.COIL_IDEAL, electrical, src, coil, rim, par, work)
    A = np.empty((n_r, n_r))
    for j in range(n_r):
        xp = x12.copy()
        xm = x12.copy()
        xp[reduced[j]] += step
        xm[reduced[j]] -= step
        fp = phys.fast_dynamics(xp, u, src, coil, rim, par, work)
        fm = phys.fast_dynamics(xm, u, src, coil, rim, par, work)
        for i in range(n_r):
            A[i, j] = (fp[reduced[i]] - fm[reduced[i]]) / (2.0 * step)
    Ad = A * dt
    A2 = _mm(Ad, Ad)
    F = np.eye(n)
    F[:n_r, :n_r] += Ad + 0.5 * A2 + _mm(A2, Ad) / 6.0
    xn = dx.copy()
    for i in range(n_r):
        xn[i] = new[reduced[i]] - x_eq[reduced[i]]
    return xn, F


@njit(cache=True)
def ekf_predict(
    dx, P, u, Q, x_eq, reduced, dt, step, src, coil, rim, par, work
):  # pragma: no cover - jitted
    """EKF prediction over one sample: :func:`ekf_transition`, then ``F P F' + Q``.

    Parameters
    ----------
    dx : ndarray, shape (n,)
    P, Q : ndarray, shape (n, n)
    u : ndarray, shape (m,)
        A.
    x_eq : ndarray, shape (12,)
    reduced : ndarray of int, shape (10,)
    dt : float
        s.
    step : float
    src, coil, rim, par, work : ndarray
        As :func:`ekf_transition`.
    """
    xn, F = ekf_transition(dx, u, x_eq, reduced, dt, step, src, coil, rim, par, work)
    Pn = _mmt(_mm(F, P), F) + Q
    return xn, _symmetrise(Pn)


@njit(cache=True)
def ekf_measure(
    dx, u, x_eq, reduced, step, src, coil, sens, mag, work
):  # pragma: no cover - jitted
    """Predicted reading h(x, u) (+ bias states) and its Jacobian, shape (3 k,), (3 k, n).

    Parameters
    ----------
    dx : ndarray, shape (n,)
    u : ndarray, shape (m,)
        A.
    x_eq : ndarray, shape (12,)
    reduced : ndarray of int, shape (10,)
    step : float
    src, coil, sens, mag, work : ndarray
        The fast model's packed measurement arguments.
    """
    n_r = reduced.shape[0]
    n = dx.shape[0]
    x12 = embed_state(dx[:n_r], x_eq, reduced)
    y = phys.fast_measurement(x12, u, src, coil, sens, mag, work)
    m = y.shape[0]
    H = np.zeros((m, n))
    for j in range(n_r):
        xp = x12.copy()
        xm = x12.copy()
        xp[reduced[j]] += step
        xm[reduced[j]] -= step
        yp = phys.fast_measurement(xp, u, src, coil, sens, mag, work)
        ym = phys.fast_measurement(xm, u, src, coil, sens, mag, work)
        for i in range(m):
            H[i, j] = (yp[i] - ym[i]) / (2.0 * step)
    if n > n_r:
        for i in range(m):
            y[i] += dx[n_r + i]
            H[i, n_r + i] = 1.0
    return y, H


@njit(cache=True)
def freeze_check(y, last, runs, run):  # pragma: no cover - jitted
    """Frozen-sensor bookkeeping (see :class:`FreezeDetector`), in place.

    Returns ``(available, frozen)`` per sensor.

    Parameters
    ----------
    y : ndarray, shape (3 k,)
        Readings, T.
    last : ndarray, shape (k, 3)
        Previous readings (updated).
    runs : ndarray of int, shape (k,)
        Run lengths (updated).
    run : int
        Run length that makes a sensor frozen.
    """
    k = runs.shape[0]
    available = np.empty(k, dtype=np.bool_)
    frozen = np.empty(k, dtype=np.bool_)
    for s in range(k):
        same = True
        finite = True
        for a in range(3):
            v = y[3 * s + a]
            if v != last[s, a]:
                same = False
            if not np.isfinite(v):
                finite = False
            last[s, a] = v
        runs[s] = runs[s] + 1 if same else 1
        frozen[s] = runs[s] >= run
        available[s] = finite and not frozen[s]
    return available, frozen


@njit(cache=True)
def odometry_covariances(x, p, unobserved):  # pragma: no cover - jitted
    """Return the pose and twist covariances of an Odometry of estimate ``x``.

    Parameters
    ----------
    x : ndarray, shape (12,)
        Estimate: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    p : ndarray, shape (>= 10, >= 10)
        Covariance of x y z alpha beta vx vy vz wx wy (then any other states).
    unobserved : float
        Variance of the unobservable yaw and yaw rate.

    Returns
    -------
    pose, twist : ndarray, shape (6, 6)
        Pose covariance over x y z and rotations about x y z; twist covariance
        over the magnet-frame velocity (nav_msgs: the child frame) and the body
        rates. Yaw and yaw rate: ``unobserved``, uncorrelated.
    """
    pose = np.zeros((6, 6))
    pose[:5, :5] = p[:5, :5]
    pose[5, 5] = unobserved
    rot = phys.rotation_matrix(x[3], x[4], x[5])
    rt = np.ascontiguousarray(rot.T)
    twist = np.zeros((6, 6))
    twist[:3, :3] = rt @ np.ascontiguousarray(p[5:8, 5:8]) @ rot
    cross = rt @ np.ascontiguousarray(p[5:8, 8:10])
    twist[:3, 3:5] = cross
    twist[3:5, :3] = cross.T
    twist[3:5, 3:5] = p[8:10, 8:10]
    twist[5, 5] = unobserved
    return pose, twist


@njit(cache=True)
def estimate_values(x, p, unobserved, out):  # pragma: no cover - jitted
    """Fill the 85 varying numbers of an estimate's Odometry (``ESTIMATE_VALUES``).

    Parameters
    ----------
    x : ndarray, shape (12,)
        Estimate: position m, ZYX Euler angles rad, world velocity m/s, body rates rad/s.
    p : ndarray, shape (>= 10, >= 10)
        Covariance of its reduced states.
    unobserved : float
        Variance of the unobservable yaw and yaw rate.
    out : ndarray, shape (85,)
        Written: position (3), quaternion x y z w (4), magnet-frame velocity
        (3), body rates (3) (``physics.kernels.odometry_fill``), then the
        pose and twist covariances of :func:`odometry_covariances`, row-major.
    """
    phys.odometry_fill(x, out[:13])
    pose, twist = odometry_covariances(x, p, unobserved)
    out[13:49] = pose.ravel()
    out[49:85] = twist.ravel()
