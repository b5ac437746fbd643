"""The linear KF's whole sample in one compiled call, on packed arrays, without BLAS.

filterpy's equations (``KalmanFilter.update`` then ``predict``): the update
with ``S = H P H' + R``, ``K = P H' S^-1`` and the Joseph form
``P = (I - K H) P (I - K H)' + K R K'``; the prediction ``x = F x + B u``,
``P = F P F' + Q``. Written for the filter's sizes (10 to 20 states, 9
readings) and structure:

* products skip the zeros of F and H (about half their entries; H's
  velocity columns are zero);
* ``P H'`` is taken as ``(H P)'`` (P is symmetric: it is symmetrised each
  step), the gain from a Cholesky solve of S (no inverse);
* symmetric results (S, the two covariances) are computed on and above the
  diagonal and mirrored: symmetric to the bit.

Cost on this filter: about 3.5 us a sample for the update and the
prediction where the general kernels (:mod:`~maglev_ros.estimation.kernels`,
a fresh array and a call per small product) took about 7.5 us; about 5 us for
the whole sample, bookkeeping included.

The estimator's model and state live in two packed arrays, floats and
ints (see :func:`packed_sizes`), so that a sample is one call of six
arguments: a numba call costs about 55 ns an argument (2 us for the 25
separate arrays of the first version). The sums are not reassociated nor
contracted (``fastmath`` ``nsz`` and ``arcp`` only; without ``nnan`` and
``ninf``: a missing reading is NaN), so they round the same on every CPU;
the results stay within 1e-14 of filterpy's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .kernels import freeze_check

#: No reassociation nor contraction: the sums as written, the same on every CPU (with
#: them they vectorised to the CPU's width, about 2 % of a sample faster, and a noisy
#: closed loop's quantised readings turned the last-bit differences into another run);
#: NaN and inf keep their meaning (missing readings are NaN)
FAST = {'nsz', 'arcp'}

__all__ = [
    'INT_HEADER',
    'I_N',
    'I_M',
    'I_MI',
    'I_K',
    'I_WINDOW',
    'I_NR',
    'I_DELAYED',
    'I_RUN',
    'I_LOST',
    'I_SAMPLES',
    'I_UNACCEPTED',
    'I_RESTARTS',
    'I_LAST_DOF',
    'I_HAS_PREV',
    'I_WHOLE',
    'packed_sizes',
    'kf_update_into',
    'kf_predict_into',
    'kf_sample_into',
    'kf_packed_step',
    'load_packed_step',
    'PACKED_STEP_SIGNATURE',
    'kf_packed_steps',
]

# header of the int array: sizes and settings, then the counters
I_N, I_M, I_MI, I_K, I_WINDOW, I_NR, I_DELAYED, I_RUN, I_LOST = range(9)
I_SAMPLES, I_UNACCEPTED, I_RESTARTS, I_LAST_DOF, I_HAS_PREV, I_WHOLE = range(9, 15)
INT_HEADER = 15


def packed_sizes(n: int, m: int, mi: int, k: int, window: int, nr: int) -> dict:
    """Offsets of the packed arrays' sections: ``{name: (start, stop)}`` per array.

    ``floats``: first the matrices of n columns, F (n, n), H (m, n), Q (n, n),
    p_init (n, n), the covariance P (n, n) and the published one (n, n); then
    those of mi columns, B (n, mi) and D (m, mi). Each group is one block of
    rows, so that a sample makes one reshape a group and slices the rows (in
    a compiled call a reshape costs about 27 ns, a slice of rows nothing).
    Then y_eq (m), u_eq (mi), r_diag (m), x_eq (12), gate (1), the state x
    (n), and the record: previous currents (mi), per-sensor NIS (k), NIS ring
    (window), the freeze check's last readings (k, 3), last NIS (1).
    ``ints``: the header (:data:`INT_HEADER` entries: n, m, mi, k, window, nr,
    delayed (0, 1, or 2: a group's mean, ``base.DELAY_MEAN``), freeze run, lost
    samples, then samples, unaccepted, restarts, last dof, has previous
    currents, and whether the whole sample runs compiled: not with the
    magnet-strength state), reduced (nr), accepted (k), dof ring (window),
    then per sensor: the freeze check's run lengths and freezes seen, the
    missing and the rejected readings (k each).

    Parameters
    ----------
    n, m, mi, k, window, nr : int
        States, readings, inputs, sensors, NIS window, reduced states.

    Returns
    -------
    dict
        ``{'ints': {...}, 'floats': {...}}``, each section
        ``(start, stop)``, and each array's ``'size'``.
    """
    out = {}
    for array, sections in (
        (
            'floats',
            [
                ('F', n * n),
                ('H', m * n),
                ('Q', n * n),
                ('p_init', n * n),
                ('P', n * n),
                ('out_p', n * n),
                ('B', n * mi),
                ('D', m * mi),
                ('y_eq', m),
                ('u_eq', mi),
                ('r_diag', m),
                ('x_eq', 12),
                ('gate', 1),
                ('x', n),
                ('prev', mi),
                ('nis_sensor', k),
                ('nis_ring', window),
                ('last', 3 * k),
                ('last_nis', 1),
            ],
        ),
        (
            'ints',
            [
                ('header', INT_HEADER),
                ('reduced', nr),
                ('accepted', k),
                ('dof_ring', window),
                ('runs', k),
                ('events', k),
                ('missing', k),
                ('rejected', k),
            ],
        ),
    ):
        at = 0
        table = {}
        for name, size in sections:
            table[name] = (at, at + size)
            at += size
        table['size'] = at
        out[array] = table
    return out


@njit(cache=True, fastmath=FAST, error_model='numpy')
def _nis3(S, s, v):  # pragma: no cover - jitted
    """``v' B^-1 v`` of the 3x3 diagonal block ``s`` of S (Cholesky); inf if not SPD."""
    o = 3 * s
    a00 = S[o, o]
    if not a00 > 0.0:
        return np.inf
    l00 = np.sqrt(a00)
    l10 = S[o + 1, o] / l00
    l20 = S[o + 2, o] / l00
    d1 = S[o + 1, o + 1] - l10 * l10
    if not d1 > 0.0:
        return np.inf
    l11 = np.sqrt(d1)
    l21 = (S[o + 2, o + 1] - l20 * l10) / l11
    d2 = S[o + 2, o + 2] - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return np.inf
    l22 = np.sqrt(d2)
    w0 = v[o] / l00
    w1 = (v[o + 1] - l10 * w0) / l11
    w2 = (v[o + 2] - l20 * w0 - l21 * w1) / l22
    return w0 * w0 + w1 * w1 + w2 * w2


@njit(cache=True, fastmath=FAST, error_model='numpy')
def kf_update_into(x, P, H, r_diag, nu, available, gate, xp, Pp):  # pragma: no cover - jitted
    """Gated Kalman update (Joseph form) into ``xp``, ``Pp``.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Prior state.
    P : ndarray, shape (n, n)
        Prior covariance, symmetric.
    H : ndarray, shape (3 k, n)
        Measurement matrix.
    r_diag : ndarray, shape (3 k,)
        Measurement variances, T^2.
    nu : ndarray, shape (3 k,)
        Innovation, T.
    available : ndarray of bool, shape (k,)
        Sensors with a reading.
    gate : float
        NIS threshold per sensor (chi-square, 3 dof).
    xp, Pp : ndarray, shapes (n,), (n, n)
        The posterior (written; the prior when no reading is accepted).

    Returns
    -------
    accepted : ndarray of bool, shape (k,)
    nis_sensor : ndarray, shape (k,)
        Each available sensor's NIS against its own 3x3 block of S (NaN if missing).
    nis : float
        NIS of the accepted readings together (0 when none).
    dof : int
        Rows used (3 per accepted sensor).
    """
    n = x.shape[0]
    m = nu.shape[0]
    k = available.shape[0]
    # the columns of H not all zero (the pose: h does not depend on the velocities)
    cols = np.empty(n, dtype=np.int64)
    q = 0
    for p in range(n):
        for a in range(m):
            if H[a, p] != 0.0:
                cols[q] = p
                q += 1
                break
    # HP = H P (m, n): P H' transposed (P symmetric)
    HP = np.zeros((m, n))
    for a in range(m):
        for c in range(q):
            p = cols[c]
            h = H[a, p]
            if h != 0.0:
                for j in range(n):
                    HP[a, j] += h * P[p, j]
    S = np.empty((m, m))
    for a in range(m):
        for b in range(a, m):
            acc = 0.0
            for c in range(q):
                acc += HP[a, cols[c]] * H[b, cols[c]]
            S[a, b] = acc
            S[b, a] = acc
        S[a, a] += r_diag[a]
    accepted = np.zeros(k, dtype=np.bool_)
    nis_sensor = np.full(k, np.nan)
    rows = 0
    for s in range(k):
        if available[s]:
            value = _nis3(S, s, nu)
            nis_sensor[s] = value
            if value <= gate:
                accepted[s] = True
                rows += 3
    if rows == 0:
        xp[:] = x
        Pp[:, :] = P
        return accepted, nis_sensor, 0.0, 0
    index = np.empty(rows, dtype=np.int64)
    j = 0
    for s in range(k):
        if accepted[s]:
            for c in range(3):
                index[j] = 3 * s + c
                j += 1
    # Cholesky factor L of the accepted rows' S; G = S^-1 (H P) (rows, n): K = G'
    L = np.zeros((rows, rows))
    for c in range(rows):
        d = S[index[c], index[c]]
        for p in range(c):
            d -= L[c, p] * L[c, p]
        if not d > 0.0:
            d = 1e-300  # not SPD to round-off (cannot happen with R > 0)
        L[c, c] = np.sqrt(d)
        for r in range(c + 1, rows):
            acc = S[index[r], index[c]]
            for p in range(c):
                acc -= L[r, p] * L[c, p]
            L[r, c] = acc / L[c, c]
    G = np.empty((rows, n))
    w = np.empty(rows)
    for r in range(rows):  # forward: L Y = HP_s, L w = nu_s
        G[r] = HP[index[r]]
        acc = nu[index[r]]
        for p in range(r):
            lrp = L[r, p]
            acc -= lrp * w[p]
            for j in range(n):
                G[r, j] -= lrp * G[p, j]
        inv = 1.0 / L[r, r]
        w[r] = acc * inv
        for j in range(n):
            G[r, j] *= inv
    nis = 0.0
    for r in range(rows):
        nis += w[r] * w[r]
    for r in range(rows - 1, -1, -1):  # backward: L' G = Y
        for p in range(r + 1, rows):
            lpr = L[p, r]
            for j in range(n):
                G[r, j] -= lpr * G[p, j]
        inv = 1.0 / L[r, r]
        for j in range(n):
            G[r, j] *= inv
    # x + K nu
    for i in range(n):
        acc = x[i]
        for r in range(rows):
            acc += G[r, i] * nu[index[r]]
        xp[i] = acc
    # Joseph form: Pp = (I - K H) P (I - K H)' + K R K', with KH = K H nonzero
    # in H's columns only: (I - K H)[j, p] = delta_jp - KH[j, p]
    KH = np.zeros((n, q))
    for r in range(rows):
        hr = index[r]
        for c in range(q):
            h = H[hr, cols[c]]
            if h != 0.0:
                for i in range(n):
                    KH[i, c] += G[r, i] * h
    M = np.empty((n, n))  # (I - K H) P
    for i in range(n):
        for j in range(n):
            M[i, j] = P[i, j]
        for c in range(q):
            v = KH[i, c]
            p = cols[c]
            for j in range(n):
                M[i, j] -= v * P[p, j]
    GR = np.empty((n, rows))  # K R
    for r in range(rows):
        rr = r_diag[index[r]]
        for i in range(n):
            GR[i, r] = G[r, i] * rr
    for i in range(n):
        for j in range(i, n):
            acc = M[i, j]
            for c in range(q):
                acc -= M[i, cols[c]] * KH[j, c]
            for r in range(rows):
                acc += GR[i, r] * G[r, j]
            Pp[i, j] = acc
            Pp[j, i] = acc
    return accepted, nis_sensor, nis, rows


@njit(cache=True, fastmath=FAST, error_model='numpy')
def kf_predict_into(x, P, F, B, u, Q, xn, Pn):  # pragma: no cover - jitted
    """Linear prediction into ``xn = F x + B u``, ``Pn = F P F' + Q`` (symmetric).

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    F : ndarray, shape (n, n)
    B : ndarray, shape (n, mi)
    u : ndarray, shape (mi,)
    Q : ndarray, shape (n, n)
    xn, Pn : ndarray, shapes (n,), (n, n)
        Written (not ``x``, ``P``).
    """
    n = x.shape[0]
    FP = np.zeros((n, n))
    for i in range(n):
        acc = 0.0
        for p in range(n):
            f = F[i, p]
            if f != 0.0:
                acc += f * x[p]
                for j in range(n):
                    FP[i, j] += f * P[p, j]
        for p in range(u.shape[0]):
            acc += B[i, p] * u[p]
        xn[i] = acc
    for i in range(n):
        for j in range(i, n):
            acc = 0.0
            for p in range(n):
                acc += FP[i, p] * F[j, p]
            acc += Q[i, j]
            Pn[i, j] = acc
            Pn[j, i] = acc


@njit(cache=True, fastmath=FAST, error_model='numpy')
def kf_sample_into(
    x, P, y, held, across, F, B, H, D, y_eq, u_eq, r_diag, Q, available, gate, xp, Pp, xn, Pn
):  # pragma: no cover - jitted
    """One KF sample: update with ``y`` (currents ``held``) into xp, Pp, predict into xn, Pn.

    Parameters
    ----------
    x, P : ndarray, shapes (n,), (n, n)
        Prior at the reading's instant.
    y : ndarray, shape (3 k,)
        Readings, T (NaN: missing, its innovation is 0).
    held : ndarray, shape (mi,)
        Currents at the reading's instant (the D feedthrough), A.
    across : ndarray, shape (mi,)
        Currents held over the prediction, A.
    F, B, H, D, Q : ndarray
        Model matrices.
    y_eq, u_eq : ndarray
        Equilibrium readings (T) and currents (A).
    r_diag : ndarray, shape (3 k,)
        Measurement variances, T^2.
    available : ndarray of bool, shape (k,)
    gate : float
    xp, Pp, xn, Pn : ndarray
        Posterior and prediction (written).

    Returns
    -------
    accepted, nis_sensor, nis, dof
        As :func:`kf_update_into`.
    """
    m = y.shape[0]
    n = x.shape[0]
    mi = held.shape[0]
    nu = np.empty(m)
    for a in range(m):
        hx = 0.0
        for p in range(n):
            hx += H[a, p] * x[p]
        dd = 0.0
        for p in range(mi):
            dd += D[a, p] * (held[p] - u_eq[p])
        v = y[a] - y_eq[a] - dd - hx
        nu[a] = v if np.isfinite(v) else 0.0
    result = kf_update_into(x, P, H, r_diag, nu, available, gate, xp, Pp)
    un = np.empty(mi)
    for p in range(mi):
        un[p] = across[p] - u_eq[p]
    kf_predict_into(xp, Pp, F, B, un, Q, xn, Pn)
    return result


@njit(cache=True, fastmath=FAST, error_model='numpy')
def _sample(y, currents, fl, ints, frozen, out):  # pragma: no cover - jitted
    n, m, mi, k = ints[I_N], ints[I_M], ints[I_MI], ints[I_K]
    window, nr = ints[I_WINDOW], ints[I_NR]
    if ints[I_WHOLE] == 0 or y.shape[0] != m or currents.shape[0] != mi:
        return False  # nothing changed: the caller steps in Python or names the input
    for p in range(mi):
        if not np.isfinite(currents[p]):
            return False
    # the model, the state and the record (packed_sizes): the matrices as row
    # slices of two reshaped blocks, the rest by offset
    rows = 5 * n + m
    block = fl[: rows * n].reshape((rows, n))
    F = block[:n]
    H = block[n : n + m]
    Q = block[n + m : 2 * n + m]
    o_pinit = (2 * n + m) * n
    P = block[3 * n + m : 4 * n + m]
    o_outp = (4 * n + m) * n
    at = rows * n
    inputs = fl[at : at + (n + m) * mi].reshape((n + m, mi))
    B = inputs[:n]
    D = inputs[n:]
    at += (n + m) * mi
    y_eq = fl[at : at + m]
    at += m
    u_eq = fl[at : at + mi]
    at += mi
    r_diag = fl[at : at + m]
    at += m
    o_xeq = at
    at += 12
    gate = fl[at]
    at += 1
    x = fl[at : at + n]
    at += n
    o_prev = at
    at += mi
    o_nis_sensor = at
    at += k
    o_nis_ring = at
    at += window
    last = fl[at : at + 3 * k].reshape((k, 3))
    j_reduced = INT_HEADER
    j_accepted = j_reduced + nr
    j_dof = j_accepted + k
    j_runs = j_dof + window
    j_events = j_runs + k
    j_missing = j_events + k
    j_rejected = j_missing + k
    # freeze check: the readings' history, the freezes seen
    available, now_frozen = freeze_check(y, last, ints[j_runs : j_runs + k], ints[I_RUN])
    for s in range(k):
        if now_frozen[s] and not frozen[s]:
            ints[j_events + s] += 1
        frozen[s] = now_frozen[s]
    # the currents at the reading's instant, and held over the prediction
    # (a group's mean: its mean currents over the group, the prediction published)
    mean = ints[I_DELAYED] == 2
    delayed = ints[I_DELAYED] >= 1
    held = np.empty(mi)
    across = np.empty(mi)
    for p in range(mi):
        if mean:
            held[p] = currents[p]
            across[p] = currents[p]
            continue
        held[p] = fl[o_prev + p] if delayed and ints[I_HAS_PREV] else currents[p]
        across[p] = 0.5 * (held[p] + currents[p]) if delayed else currents[p]
    xp = np.empty(n)
    Pp = np.empty((n, n))
    # the prior (x, P) is not read after the update: the prediction overwrites it
    accepted, nis_sensor, nis, dof = kf_sample_into(
        x, P, y, held, across, F, B, H, D, y_eq, u_eq, r_diag, Q, available, gate, xp, Pp, x, P
    )
    n_available = 0
    for s in range(k):
        if available[s]:
            n_available += 1
        else:
            ints[j_missing + s] += 1
    if dof < 3 * n_available:
        for s in range(k):
            if available[s] and not accepted[s]:
                ints[j_rejected + s] += 1
    # published: the prediction (delayed reading) or the posterior
    xo = x if delayed else xp
    po = P if delayed else Pp
    for i in range(n):
        for j in range(n):
            fl[o_outp + i * n + j] = po[i, j]
    for i in range(12):
        out[i] = fl[o_xeq + i]
    for i in range(nr):
        out[ints[j_reduced + i]] += xo[i]
    # the record: NIS window, last sample, counters, a restart when lost
    slot = ints[I_SAMPLES] % window
    fl[o_nis_ring + slot] = nis
    ints[j_dof + slot] = dof
    fl[fl.shape[0] - 1] = nis
    ints[I_LAST_DOF] = dof
    for s in range(k):
        ints[j_accepted + s] = 1 if accepted[s] else 0
        fl[o_nis_sensor + s] = nis_sensor[s]
    for p in range(mi):
        fl[o_prev + p] = currents[p]
    ints[I_HAS_PREV] = 1
    ints[I_SAMPLES] += 1
    ints[I_UNACCEPTED] = 0 if dof else ints[I_UNACCEPTED] + 1
    if ints[I_UNACCEPTED] >= ints[I_LOST]:  # restart from the prior at the equilibrium
        for i in range(n):
            x[i] = 0.0
        for i in range(n):
            for j in range(n):
                P[i, j] = fl[o_pinit + i * n + j]
        for i in range(n * n):
            fl[o_outp + i] = fl[o_pinit + i]
        for i in range(12):
            out[i] = fl[o_xeq + i]
        ints[I_RESTARTS] += 1
        ints[I_UNACCEPTED] = 0
    return True


@njit(cache=True, fastmath=FAST, error_model='numpy')
def kf_packed_step(y, currents, fl, ints, frozen, out):  # pragma: no cover - jitted
    """One whole KF sample on the packed arrays (see :func:`packed_sizes`), in place.

    What :meth:`Estimator.step <maglev_ros.estimation.base.Estimator.step>`
    does for the KF (the same operations in the same order as
    :meth:`KalmanEstimator._sample <maglev_ros.estimation.linear.KalmanEstimator._sample>`,
    so the same numbers): the freeze check, the currents at the reading's
    instant and over the prediction, :func:`kf_sample_into`, the missing and
    rejected counts, the NIS window and the counters, and a restart after
    ``lost_samples`` samples without an accepted reading.

    Parameters
    ----------
    y : ndarray, shape (3 k,)
        Readings, T (NaN: missing).
    currents : ndarray, shape (mi,)
        The sample's currents, A.
    fl, ints : ndarray
        The packed floats (the model, the state and the record) and ints
        (sizes, settings, counters and the record), updated in place.
    frozen : ndarray of bool, shape (k,)
        Sensors frozen now (updated in place).
    out : ndarray, shape (12,)
        The published estimate (written; a fresh array from the caller: cheaper
        than one returned by a compiled function).

    Compiled for float64 C arrays only (the signature is given): anything else
    raises ``TypeError`` at once instead of compiling again (seconds in a
    real-time loop).

    Returns
    -------
    bool
        False (and nothing changed) when ``y`` or ``currents`` has the wrong
        length, a current is not finite, or the filter has the magnet-strength
        state (its H is linearised in Python each sample).
    """
    return _sample(y, currents, fl, ints, frozen, out)


#: The one signature of :func:`kf_packed_step`: float64, int64 and bool C arrays.
PACKED_STEP_SIGNATURE = (
    'boolean(float64[::1], float64[::1], float64[::1], int64[::1], boolean[::1], float64[::1])'
)


def load_packed_step() -> None:
    """Compile (or load from the cache) :func:`kf_packed_step` for its one signature, once.

    Called when a KF is built, not at import: a compile then happens where the
    first run's progress line and stop signals are watched
    (:mod:`maglev_ros.compile_watch`). Further compiles are disabled, so a call
    with other types (a list, a strided row) raises ``TypeError`` instead of
    compiling a second signature.
    """
    if not kf_packed_step.signatures:
        kf_packed_step.compile(PACKED_STEP_SIGNATURE)
        kf_packed_step.disable_compile()


@njit(cache=True, fastmath=FAST, error_model='numpy')
def kf_packed_steps(ys, us, fl, ints, frozen, x_out, p_out, at):  # pragma: no cover - jitted
    """Many KF samples in one call: :func:`kf_packed_step` on each row, in order.

    Parameters
    ----------
    ys : ndarray, shape (N, 3 k)
        Readings, T.
    us : ndarray, shape (N, mi)
        Currents, A.
    fl, ints, frozen : ndarray
        As :func:`kf_packed_step`.
    x_out : ndarray, shape (N, 12)
        The estimates (written).
    p_out : ndarray, shape (N, n, n)
        Their covariances (written).
    at : int
        The published covariance's offset in ``fl`` (:func:`packed_sizes`).
    """
    n = ints[I_N]
    for i in range(ys.shape[0]):
        _sample(ys[i], us[i], fl, ints, frozen, x_out[i])
        p_out[i] = fl[at : at + n * n].reshape((n, n))
