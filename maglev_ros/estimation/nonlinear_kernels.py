"""Compiled (numba) steps of the EKF and the UKF: a whole sample in one call.

The equations are filterpy's: ``ExtendedKalmanFilter`` (predict ``F P F' +
Q``; update with the Jacobian H, here gated per sensor and in Joseph form,
:func:`~maglev_ros.estimation.kernels.gated_update`) and
``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints`` (sigma points from
the Cholesky factor of ``(n + lambda) P``, the unscented transform, ``P - K S
K'``). The model is :mod:`~maglev_ros.estimation.filter_model`'s, ``full``
(RK4, fresh Jacobians) or ``fast`` (exponential Euler, see below).

EKF ``fast``: the mean takes one exponential-Euler step with the Jacobian A
of f; A is refreshed one column per sample (forward differences, one more
evaluation of f), so it is at most ``len(reduced)`` samples (2 ms at 5 kHz)
old, and all of it after a reset. Per sample: two evaluations of f where the
full prediction takes 24.

UKF ``fast``: each sigma point takes one exponential-Euler step; A is the
statistical linearisation the sigma points give for free (the differences of
f across each pair of points against the Cholesky factor). The magnetic
wrench, the cost of f, is evaluated at the centre only: a point spread along
the pose takes the centre's wrench plus the wrench's Jacobian in the pose
times its offset (the rigid-body rates, rotation included, evaluated at the
point itself). That Jacobian is refreshed one pose column per sample (forward
differences, one more wrench), so it is at most 5 samples (1 ms at 5 kHz)
old, and all of it after a reset. Per sample: two wrenches where the
exponential-Euler step of every point took 11 (the points of distinct pose)
and RK4 takes 84.

Both: h and the magnetic wrench (the cost of f) depend on the pose (x, y,
z, alpha, beta) only. So the measurement Jacobian's velocity columns are
zero; sigma points whose pose equals the centre's (those spread along a
velocity or a bias, the Cholesky factor being lower triangular) share its h
and, in the fast prediction, its wrench (only the rigid-body rates are
evaluated again), as do the EKF's Jacobian columns of the velocities and
rates. Exactly: the same inputs, the same operations.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..physics import kernels as phys
from .filter_model import embed, filter_measurement, measurement_jacobian, series_transition
from .kernels import (
    _mm,
    _mmt,
    _mv,
    _symmetrise,
    freeze_check,
    gate_sensors,
    gated_update,
    spd_inverse,
)

__all__ = [
    'ekf_predict_full',
    'ekf_predict_fast',
    'ekf_update',
    'ekf_step',
    'sigma_points',
    'ukf_predict',
    'ukf_update',
    'ukf_step',
]


@njit(cache=True)
def _rates(x12, u, src, coil, rim, par, work, reduced):  # pragma: no cover - jitted
    f = phys.fast_dynamics(x12, u, src, coil, rim, par, work)
    n_r = reduced.shape[0]
    out = np.empty(n_r)
    for i in range(n_r):
        out[i] = f[reduced[i]]
    return out


@njit(cache=True)
def _wrench(x12, u, src, coil, rim, par, work):  # pragma: no cover - jitted
    """Return the magnetic force and torque of ``fast_dynamics`` (its cost), and R."""
    r = phys.rotation_matrix(x12[3], x12[4], x12[5])
    return phys.rim_force_torque(x12, u, src, coil, rim, par, work, r), r


@njit(cache=True)
def _rates_with(x12, wrench, r, par, reduced):  # pragma: no cover - jitted
    """Reduced rates of ``fast_dynamics`` from a known wrench and rotation (same operations)."""
    f = phys.rigid_body_rates(
        x12,
        wrench,
        par[phys.P_MASS],
        par[phys.P_IXX : phys.P_IZZ + 1],
        int(par[phys.P_KINEMATICS]),
        r,
    )
    n_r = reduced.shape[0]
    out = np.empty(n_r)
    for i in range(n_r):
        out[i] = f[reduced[i]]
    return out


@njit(cache=True)
def _rk4(x12, u, dt, src, coil, rim, par, work, reduced, x_eq):  # pragma: no cover - jitted
    """Reduced deviation after one RK4 step of the 12-state from ``x12``."""
    new = phys.rk4_sample(x12, u, dt, 1, phys.COIL_IDEAL, np.ones(3), src, coil, rim, par, work)
    n_r = reduced.shape[0]
    out = np.empty(n_r)
    for i in range(n_r):
        out[i] = new[reduced[i]] - x_eq[reduced[i]]
    return out


@njit(cache=True)
def _transition(A, dt, n):  # pragma: no cover - jitted
    n_r = A.shape[0]
    Fr, M = series_transition(A, dt)
    F = np.eye(n)
    F[:n_r, :n_r] = Fr
    return F, M


@njit(cache=True)
def _columns_due(cursor, n):  # pragma: no cover - jitted
    """Columns ``first:last`` of a Jacobian to refresh now; advance ``cursor`` (1,) in place.

    One column a sample, in turn; every column when ``cursor[0]`` is negative
    (after a reset).
    """
    first, last = cursor[0], cursor[0] + 1
    if cursor[0] < 0:
        first, last = 0, n
    cursor[0] = last % n
    return first, last


@njit(cache=True)
def ekf_predict_full(
    dx, P, u, Q, x_eq, reduced, dt, step, src, coil, rim, par, work
):  # pragma: no cover - jitted
    """EKF prediction with the full model: one RK4 step, A by central differences.

    Returns ``(x, F P F' + Q)``; F is the series ``exp(A dt)`` (third order).

    Parameters
    ----------
    dx : ndarray, shape (n,)
        Reduced deviation (+ biases).
    P, Q : ndarray, shape (n, n)
    u : ndarray, shape (n_s,)
        Currents held over the sample, A.
    x_eq : ndarray, shape (12,)
    reduced : ndarray of int, shape (10,)
    dt, step : float
        Sample period (s) and finite-difference step.
    src, coil, rim, par, work : ndarray
        The fast model's packed arguments.
    """
    n_r = reduced.shape[0]
    n = dx.shape[0]
    x12 = embed(dx, x_eq, reduced)
    A = np.empty((n_r, n_r))
    for j in range(n_r):
        xp = x12.copy()
        xm = x12.copy()
        xp[reduced[j]] += step
        xm[reduced[j]] -= step
        fp = _rates(xp, u, src, coil, rim, par, work, reduced)
        fm = _rates(xm, u, src, coil, rim, par, work, reduced)
        for i in range(n_r):
            A[i, j] = (fp[i] - fm[i]) / (2.0 * step)
    F, _ = _transition(A, dt, n)
    xn = dx.copy()
    xn[:n_r] = _rk4(x12, u, dt, src, coil, rim, par, work, reduced, x_eq)
    Pn = _mmt(_mm(F, P), F) + Q
    return xn, _symmetrise(Pn)


@njit(cache=True)
def ekf_predict_fast(
    dx, P, u, Q, A, cursor, x_eq, reduced, dt, step, src, coil, rim, par, work
):  # pragma: no cover - jitted
    """EKF prediction with the fast model: exponential Euler, A one column per sample.

    ``A`` (r, r) and ``cursor`` (1,) int64 are the filter's and updated in
    place: ``cursor[0]`` is the column refreshed now (negative: all of them).

    Parameters
    ----------
    dx, P, u, Q, x_eq, reduced, dt, step, src, coil, rim, par, work
        As :func:`ekf_predict_full`.
    A : ndarray, shape (10, 10)
        Jacobian of the reduced dynamics, 1/s (updated).
    cursor : ndarray of int64, shape (1,)
        Next column to refresh (updated).
    """
    n_r = reduced.shape[0]
    n = dx.shape[0]
    x12 = embed(dx, x_eq, reduced)
    w0, r0 = _wrench(x12, u, src, coil, rim, par, work)
    f0 = _rates_with(x12, w0, r0, par, reduced)
    first, last = _columns_due(cursor, n_r)
    for j in range(first, last):
        xp = x12.copy()
        xp[reduced[j]] += step
        if reduced[j] >= 6:  # a velocity or a rate: the same pose, the same wrench
            fp = _rates_with(xp, w0, r0, par, reduced)
        else:
            fp = _rates(xp, u, src, coil, rim, par, work, reduced)
        for i in range(n_r):
            A[i, j] = (fp[i] - f0[i]) / step
    F, M = _transition(A, dt, n)
    xn = dx.copy()
    for i in range(n_r):
        acc = 0.0
        for j in range(n_r):
            acc += M[i, j] * f0[j]
        xn[i] += acc
    Pn = _mmt(_mm(F, P), F) + Q
    return xn, _symmetrise(Pn)


@njit(cache=True)
def ekf_update(
    dx,
    P,
    y,
    u,
    available,
    r_diag,
    gate,
    x_eq,
    reduced,
    step,
    y0,
    G,
    sens,
    mag,
    own_src,
    own_coil,
    work,
):  # pragma: no cover - jitted
    """EKF measurement update: h and its Jacobian at ``dx``, gated per sensor, Joseph form.

    Returns what :func:`~maglev_ros.estimation.kernels.gated_update` returns.

    Parameters
    ----------
    dx, P : ndarray
        Prior.
    y : ndarray, shape (3 k,)
        Readings, T (NaN: missing).
    u : ndarray, shape (n_s,)
        Currents at the readings' instant, A.
    available : ndarray of bool, shape (k,)
    r_diag : ndarray, shape (3 k,)
    gate : float
    x_eq, reduced, step
    y0, G, sens, mag, own_src, own_coil, work
        The measurement model (:mod:`~maglev_ros.estimation.filter_model`).
    """
    h, H = measurement_jacobian(
        dx, u, x_eq, reduced, step, y0, G, sens, mag, own_src, own_coil, work
    )
    m = y.shape[0]
    nu = np.empty(m)
    for i in range(m):
        v = y[i] - h[i]
        nu[i] = v if np.isfinite(v) else 0.0
    return gated_update(dx, P, H, r_diag, nu, available, gate)


@njit(cache=True)
def _sample_currents(currents, prev, delayed):  # pragma: no cover - jitted
    """Currents at the reading's instant and held over the prediction (see ``base``)."""
    held = currents
    across = currents
    if delayed:
        if np.isfinite(prev[0]):
            held = prev
        across = 0.5 * (held + currents)
    return held, across


@njit(cache=True)
def _freeze(y, last, runs, run, frozen, events):  # pragma: no cover - jitted
    available, now_frozen = freeze_check(y, last, runs, run)
    for s in range(available.shape[0]):
        if now_frozen[s] and not frozen[s]:
            events[s] += 1
        frozen[s] = now_frozen[s]
    return available


@njit(cache=True)
def _count(available, accepted, dof, missing, rejected):  # pragma: no cover - jitted
    n_available = 0
    for s in range(available.shape[0]):
        if available[s]:
            n_available += 1
        else:
            missing[s] += 1
    if dof < 3 * n_available:
        for s in range(available.shape[0]):
            if available[s] and not accepted[s]:
                rejected[s] += 1


@njit(cache=True)
def _keep(x, P, xn, Pn, Pout, out_p, accepted, nis_sensor, accepted_out, nis_sensor_out):
    # pragma: no cover - jitted
    """Write the next prior (x, P), the published covariance and the gate's verdicts."""
    n = x.shape[0]
    for i in range(n):
        x[i] = xn[i]
        for j in range(n):
            P[i, j] = Pn[i, j]
            out_p[i, j] = Pout[i, j]
    for s in range(accepted.shape[0]):
        accepted_out[s] = accepted[s]
        nis_sensor_out[s] = nis_sensor[s]


@njit(cache=True)
def _publish(x, x_eq, reduced, out_x):  # pragma: no cover - jitted
    out_x[:] = x_eq
    for i in range(reduced.shape[0]):
        out_x[reduced[i]] += x[i]


@njit(cache=True)
def ekf_step(
    y,
    currents,
    prev,
    delayed,
    fast,
    x,
    P,
    Q,
    A,
    cursor,
    r_diag,
    gate,
    last,
    runs,
    run,
    frozen,
    events,
    missing,
    rejected,
    x_eq,
    reduced,
    dt,
    step,
    src,
    coil,
    rim,
    par,
    work,
    y0,
    G,
    sens,
    mag,
    own_src,
    own_coil,
    out_x,
    out_p,
    accepted_out,
    nis_sensor_out,
):  # pragma: no cover - jitted
    """One whole EKF sample: freeze check, update, predict, counts (as ``Estimator.step``).

    Returns ``(nis, dof)``; the next prior is written into ``x`` and ``P``,
    the published estimate and its covariance into ``out_x`` and ``out_p``,
    the gate's verdicts into ``accepted_out`` and ``nis_sensor_out`` (arrays
    written in place: a compiled function's returned arrays cost about 0.5 us
    each to hand back to Python).

    Parameters
    ----------
    y, currents, prev, delayed
        As :func:`~maglev_ros.estimation.kernels.kf_step`.
    fast : bool
        The fast prediction (:func:`ekf_predict_fast`) or the full one.
    x, P, Q, A, cursor
        Filter state, process noise and the fast prediction's Jacobian.
    r_diag, gate, last, runs, run, frozen, events, missing, rejected, x_eq, reduced
        As :func:`~maglev_ros.estimation.kernels.kf_step`.
    dt, step : float
    src, coil, rim, par, work
        The fast model's packed arguments.
    y0, G, sens, mag, own_src, own_coil
        The measurement model.
    out_x : ndarray, shape (12,)
        The published estimate (written).
    out_p : ndarray, shape (n, n)
        Its covariance (written).
    accepted_out : ndarray of bool, shape (k,)
    nis_sensor_out : ndarray, shape (k,)
        Each sensor's verdict and NIS (written).
    """
    available = _freeze(y, last, runs, run, frozen, events)
    held, across = _sample_currents(currents, prev, delayed)
    xu, Pu, accepted, nis_sensor, nis, dof = ekf_update(
        x,
        P,
        y,
        held,
        available,
        r_diag,
        gate,
        x_eq,
        reduced,
        step,
        y0,
        G,
        sens,
        mag,
        own_src,
        own_coil,
        work,
    )
    if fast:
        xn, Pn = ekf_predict_fast(
            xu, Pu, across, Q, A, cursor, x_eq, reduced, dt, step, src, coil, rim, par, work
        )
    else:
        xn, Pn = ekf_predict_full(
            xu, Pu, across, Q, x_eq, reduced, dt, step, src, coil, rim, par, work
        )
    _count(available, accepted, dof, missing, rejected)
    _publish(xn if delayed else xu, x_eq, reduced, out_x)
    _keep(
        x, P, xn, Pn, Pn if delayed else Pu, out_p, accepted, nis_sensor, accepted_out,
        nis_sensor_out,
    )  # fmt: skip
    return nis, dof


# ---------------------------------------------------------------------- UKF
@njit(cache=True)
def _cholesky(P):  # pragma: no cover - jitted
    """Lower Cholesky factor (numpy's; filterpy takes scipy's upper one, its transpose)."""
    return np.linalg.cholesky(P)


@njit(cache=True)
def sigma_points(x, P, lam):  # pragma: no cover - jitted
    """Merwe's scaled sigma points (filterpy's order): x, x + L_k, x - L_k; (2 n + 1, n).

    ``L`` is the lower Cholesky factor of ``(n + lam) P``; its column k is the
    row k of filterpy's upper factor.

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    lam : float
        ``alpha^2 (n + kappa) - n``.
    """
    n = x.shape[0]
    L = _cholesky((n + lam) * P)
    sig = np.empty((2 * n + 1, n))
    sig[0] = x
    for k in range(n):
        for i in range(n):
            sig[1 + k, i] = x[i] + L[i, k]
            sig[1 + n + k, i] = x[i] - L[i, k]
    return sig, L


@njit(cache=True)
def _same_reduced(a, b, n_r):  # pragma: no cover - jitted
    for i in range(n_r):
        if a[i] != b[i]:
            return False
    return True


@njit(cache=True)
def _same_pose(a, b, reduced):  # pragma: no cover - jitted
    for i in range(reduced.shape[0]):
        if reduced[i] < 6 and a[i] != b[i]:
            return False
    return True


@njit(cache=True)
def _unscented(sig, Wm, Wc):  # pragma: no cover - jitted
    """Weighted mean and covariance of the rows of ``sig`` (no noise added)."""
    p, n = sig.shape
    mean = np.zeros(n)
    for i in range(p):
        for a in range(n):
            mean[a] += Wm[i] * sig[i, a]
    cov = np.zeros((n, n))
    d = np.empty(n)
    for i in range(p):
        for a in range(n):
            d[a] = sig[i, a] - mean[a]
        w = Wc[i]
        for a in range(n):
            wa = w * d[a]
            for b in range(n):
                cov[a, b] += wa * d[b]
    return mean, cov


@njit(cache=True)
def _pose_wrench(x12, w0, J, pose, reduced):  # pragma: no cover - jitted
    """Return the wrench at ``x12`` from the one at ``pose`` (12,) and its Jacobian (6, n_pose)."""
    w = w0.copy()
    for j in range(J.shape[1]):
        d = x12[reduced[j]] - pose[reduced[j]]
        if d != 0.0:
            for a in range(6):
                w[a] += J[a, j] * d
    return w


@njit(cache=True)
def ukf_predict(
    x, P, u, Q, Wm, Wc, lam, fast, J, cursor, step, x_eq, reduced, dt, src, coil, rim, par, work
):  # pragma: no cover - jitted
    """UKF prediction: sigma points of (x, P) through f, their unscented transform plus Q.

    Returns ``(x, P, sigmas_f)``, ``sigmas_f`` the sigma points of the
    predicted (x, P) (filterpy draws them afresh for the update).

    Parameters
    ----------
    x : ndarray, shape (n,)
    P, Q : ndarray, shape (n, n)
    u : ndarray, shape (n_s,)
        Currents held over the sample, A.
    Wm, Wc : ndarray, shape (2 n + 1,)
        Weights of the mean and of the covariance.
    lam : float
        Sigma-point scaling ``alpha^2 (n + kappa) - n``.
    fast : bool
        Exponential Euler with the statistical linearisation (else RK4).
    J : ndarray, shape (6, n_pose)
        Fast: the wrench's Jacobian in the pose states (the reduced states
        before the first velocity), N/m, N, N m/m, N m (updated).
    cursor : ndarray of int64, shape (1,)
        Fast: the pose column of J refreshed now (negative: all of them; updated).
    step : float
        Finite-difference step of J, m or rad.
    x_eq, reduced, dt
    src, coil, rim, par, work
        The fast model's packed arguments.
    """
    n_r = reduced.shape[0]
    n = x.shape[0]
    sig, L = sigma_points(x, P, lam)
    p = sig.shape[0]
    out = sig.copy()
    if fast:
        rates = np.empty((p, n_r))
        x0 = embed(sig[0], x_eq, reduced)
        w0, r0 = _wrench(x0, u, src, coil, rim, par, work)
        first, last = _columns_due(cursor, J.shape[1])
        for j in range(first, last):  # the wrench's Jacobian, one pose column a sample
            xp = x0.copy()
            xp[reduced[j]] += step
            wp, _ = _wrench(xp, u, src, coil, rim, par, work)
            for a in range(6):
                J[a, j] = (wp[a] - w0[a]) / step
        for i in range(p):
            if i > 0 and _same_reduced(sig[i], sig[0], n_r):
                rates[i] = rates[0]
            elif _same_pose(sig[i], sig[0], reduced):  # the centre's wrench
                rates[i] = _rates_with(embed(sig[i], x_eq, reduced), w0, r0, par, reduced)
            else:  # the centre's wrench moved along its Jacobian; this point's rotation
                xi = embed(sig[i], x_eq, reduced)
                ri = phys.rotation_matrix(xi[3], xi[4], xi[5])
                rates[i] = _rates_with(xi, _pose_wrench(xi, w0, J, x0, reduced), ri, par, reduced)
        # statistical linearisation: f(x + L_j) - f(x - L_j) = 2 A L_j (reduced block)
        D = np.empty((n_r, n_r))
        for j in range(n_r):
            for i in range(n_r):
                D[i, j] = 0.5 * (rates[1 + j, i] - rates[1 + n + j, i])
        A = np.empty((n_r, n_r))
        for i in range(n_r):  # A Lr = D, Lr lower triangular: back substitution per row
            for j in range(n_r - 1, -1, -1):
                acc = D[i, j]
                for q in range(j + 1, n_r):
                    acc -= A[i, q] * L[q, j]
                A[i, j] = acc / L[j, j]
        _, M = series_transition(A, dt)
        for i in range(p):
            for a in range(n_r):
                acc = 0.0
                for b in range(n_r):
                    acc += M[a, b] * rates[i, b]
                out[i, a] += acc
    else:
        for i in range(p):
            if i > 0 and _same_reduced(sig[i], sig[0], n_r):
                out[i, :n_r] = out[0, :n_r]
            else:
                out[i, :n_r] = _rk4(
                    embed(sig[i], x_eq, reduced), u, dt, src, coil, rim, par, work, reduced, x_eq
                )
    mean, cov = _unscented(out, Wm, Wc)
    cov += Q
    # as filterpy: the update's sigma points are drawn afresh from the prediction
    fresh, _ = sigma_points(mean, cov, lam)
    return mean, cov, fresh


@njit(cache=True)
def ukf_update(
    x,
    P,
    sigmas_f,
    y,
    u,
    available,
    r_diag,
    gate,
    Wm,
    Wc,
    x_eq,
    reduced,
    y0,
    G,
    sens,
    mag,
    own_src,
    own_coil,
    work,
):  # pragma: no cover - jitted
    """UKF update with a chi-square gate per sensor: filterpy's update on the accepted rows.

    The gate uses each sensor's block of S from the unscented transform of
    the predicted sigma points through h; the accepted rows then update
    (``K = Pxz S^-1``, ``P - K S K'``, symmetrised). Returns ``(x, P,
    accepted, nis_sensor, nis, dof)`` as
    :func:`~maglev_ros.estimation.kernels.gated_update`.

    Parameters
    ----------
    x, P : ndarray
        Prior (the unscented transform of ``sigmas_f``, plus Q).
    sigmas_f : ndarray, shape (2 n + 1, n)
        The sigma points of the prior (x, P).
    y : ndarray, shape (3 k,)
        Readings, T.
    u : ndarray, shape (n_s,)
        Currents at the readings' instant, A.
    available, r_diag, gate
        As :func:`~maglev_ros.estimation.kernels.gated_update`.
    Wm, Wc : ndarray, shape (2 n + 1,)
    x_eq, reduced
    y0, G, sens, mag, own_src, own_coil, work
        The measurement model.
    """
    n_r = reduced.shape[0]
    p, n = sigmas_f.shape
    m = y.shape[0]
    sh = np.empty((p, m))
    for i in range(p):
        if i > 0 and _same_pose(sigmas_f[i], sigmas_f[0], reduced):
            sh[i] = sh[0, :]  # h depends on the pose (and the biases) only
            if n > n_r:  # the centre's bias removed, this point's added
                for a in range(m):
                    sh[i, a] += sigmas_f[i, n_r + a] - sigmas_f[0, n_r + a]
        else:
            sh[i] = filter_measurement(
                sigmas_f[i], u, x_eq, reduced, y0, G, sens, mag, own_src, own_coil, work
            )
    zp, S = _unscented(sh, Wm, Wc)
    for a in range(m):
        S[a, a] += r_diag[a]
    nu = y - zp
    accepted, nis_sensor, index = gate_sensors(S, nu, available, gate)
    rows = index.shape[0]
    if rows == 0:
        return x.copy(), P.copy(), accepted, nis_sensor, 0.0, 0
    Ss = np.empty((rows, rows))
    vs = np.empty(rows)
    for a in range(rows):
        vs[a] = nu[index[a]]
        for b in range(rows):
            Ss[a, b] = S[index[a], index[b]]
    Pxz = np.zeros((n, rows))
    for i in range(p):
        w = Wc[i]
        for a in range(n):
            da = w * (sigmas_f[i, a] - x[a])
            for b in range(rows):
                Pxz[a, b] += da * (sh[i, index[b]] - zp[index[b]])
    SI = spd_inverse(Ss)
    K = _mm(Pxz, SI)
    xn = x.copy()
    for a in range(n):
        acc = 0.0
        for b in range(rows):
            acc += K[a, b] * vs[b]
        xn[a] += acc
    Pn = P - _mmt(_mm(K, Ss), K)
    nis = vs @ _mv(SI, vs)
    return xn, _symmetrise(Pn), accepted, nis_sensor, nis, rows


@njit(cache=True)
def ukf_step(
    y,
    currents,
    prev,
    delayed,
    fast,
    J,
    cursor,
    step,
    x,
    P,
    sigmas_f,
    Q,
    Wm,
    Wc,
    lam,
    r_diag,
    gate,
    last,
    runs,
    run,
    frozen,
    events,
    missing,
    rejected,
    x_eq,
    reduced,
    dt,
    src,
    coil,
    rim,
    par,
    work,
    y0,
    G,
    sens,
    mag,
    own_src,
    own_coil,
    out_x,
    out_p,
    accepted_out,
    nis_sensor_out,
):  # pragma: no cover - jitted
    """One whole UKF sample: freeze check, update, predict, counts (as ``Estimator.step``).

    Returns ``(nis, dof)``; the next prior is written into ``x``, ``P`` and
    ``sigmas_f``, the rest as :func:`ekf_step` writes it.

    Parameters
    ----------
    y, currents, prev, delayed
        As :func:`~maglev_ros.estimation.kernels.kf_step`.
    fast : bool
        The fast prediction (see :func:`ukf_predict`).
    J, cursor, step
        The fast prediction's wrench Jacobian (see :func:`ukf_predict`).
    x, P, sigmas_f, Q, Wm, Wc, lam
        Filter state, its predicted sigma points, process noise, weights, scaling.
    r_diag, gate, last, runs, run, frozen, events, missing, rejected, x_eq, reduced
        As :func:`~maglev_ros.estimation.kernels.kf_step`.
    dt : float
    src, coil, rim, par, work
        The fast model's packed arguments.
    y0, G, sens, mag, own_src, own_coil
        The measurement model.
    out_x, out_p, accepted_out, nis_sensor_out : ndarray
        As :func:`ekf_step` (written).
    """
    available = _freeze(y, last, runs, run, frozen, events)
    held, across = _sample_currents(currents, prev, delayed)
    xu, Pu, accepted, nis_sensor, nis, dof = ukf_update(
        x,
        P,
        sigmas_f,
        y,
        held,
        available,
        r_diag,
        gate,
        Wm,
        Wc,
        x_eq,
        reduced,
        y0,
        G,
        sens,
        mag,
        own_src,
        own_coil,
        work,
    )
    xn, Pn, sn = ukf_predict(
        xu, Pu, across, Q, Wm, Wc, lam, fast, J, cursor, step, x_eq, reduced, dt, src, coil,
        rim, par, work,
    )  # fmt: skip
    _count(available, accepted, dof, missing, rejected)
    _publish(xn if delayed else xu, x_eq, reduced, out_x)
    _keep(
        x, P, xn, Pn, Pn if delayed else Pu, out_p, accepted, nis_sensor, accepted_out,
        nis_sensor_out,
    )  # fmt: skip
    for i in range(sn.shape[0]):
        for j in range(sn.shape[1]):
            sigmas_f[i, j] = sn[i, j]
    return nis, dof
