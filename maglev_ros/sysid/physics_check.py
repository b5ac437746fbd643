"""The physics check: an identified model's frequency response against the linearisation.

The linearisation of the Maggy model about its equilibrium
(``physics.linearize(model).reduced()``: ``dx = A x + B i``, ``B = C x + D i``,
i the coil currents in A, B the fields in T) gives the true local transfer
function from a combination of coil inputs to one field component.  It is
sampled as the data are:

* the input is held over each sample (exact zero-order hold, ``expm`` of the
  augmented matrix), ``u[t]`` acting over ``[t, t + 1)`` - the sample
  convention of a lockstep simulation, where the command of sample ``t`` is
  logged at its time and steps the model to ``t + 1``;
* without coil dynamics the current at sample ``t`` is the previous command,
  so the feedthrough ``D`` enters as ``D u[t - 1]``; with coil dynamics
  (``coil_time_constant = L/R``, the board's current drive
  ``L di/dt = R (i_cmd - i)``) the currents are extra states;
* the sensor delay (``delay_samples``, the board has 1) multiplies by
  ``z^-delay``.

So ``G(z) = z^-d [C_d (zI - A_d)^-1 B_d + D z^-1]`` (ideal coils).  The
linearised plant is unstable open loop (the x/y modes), but its frequency
response on the unit circle is well defined and is what a consistent
closed-loop estimate converges to.

:func:`compare_response` evaluates an identified model and the reference
over a band and returns the deviation ``G_id / G_true`` in dB and degrees
(max and RMS), and the unstable modes of each: the magnet's x and y modes
grow at about 30-50 1/s, and a closed-loop estimate that puts the mirrored,
stable pole in their place matches the gain but not the phase (up to 180
degrees at low frequency).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

__all__ = [
    'PAIRS',
    'RESONANCE_DAMPING',
    'RESONANCE_WIDTH',
    'UNSTABLE_RATE',
    'FrequencyDeviation',
    'LocalPlant',
    'PhysicsCheckError',
    'compare_response',
    'local_plant',
    'unstable_rates',
]

#: Damping ratio below which an oscillatory pole of the reference is a resonance
#: whose neighbourhood :func:`compare_response` leaves out.
RESONANCE_DAMPING = 0.01
#: Half-width (Hz) of the band left out around each such resonance.
RESONANCE_WIDTH = 1.0
#: Growth rate (1/s) above which a pole counts as unstable (time constant under 1 s):
#: an identified pole a hair outside the unit circle is no unstable mode.
UNSTABLE_RATE = 1.0


def unstable_rates(poles: np.ndarray, Ts: float) -> np.ndarray:
    """Growth rates of the unstable poles of a discrete model, largest first.

    Parameters
    ----------
    poles : array_like, shape (n,)
        Poles in z.
    Ts : float
        Sample time, s.

    Returns
    -------
    ndarray, shape (k,)
        ``ln|z| / Ts`` (1/s) of each pole growing faster than
        :data:`UNSTABLE_RATE`; a complex pair counted once.
    """
    p = np.asarray(poles, dtype=complex).ravel()
    p = p[p.imag >= 0]
    rates = np.log(np.maximum(np.abs(p), 1e-300)) / float(Ts)
    return np.sort(rates[rates > UNSTABLE_RATE])[::-1]


#: Antisymmetric input pairs in the solenoid order x+, x-, y+, y- (as maglev-lab's
#: ``u_x``: x+ = u, x- = -u).
PAIRS = {'x': (1.0, -1.0, 0.0, 0.0), 'y': (0.0, 0.0, 1.0, -1.0)}


class PhysicsCheckError(ValueError):
    """A bad argument of the physics check (names the value)."""


@dataclass(frozen=True)
class LocalPlant:
    """Sampled SISO linearisation ``y[t] = C_d x[t] + D_d u[t]`` delayed by ``delay`` samples.

    Attributes
    ----------
    A, B, C : ndarray, shapes (n, n), (n,), (n,)
        Discrete state-space model (input: the weighted coil combination, A;
        output: one field component, T).  Without coil dynamics the state
        holds the previous input as its last element (the ``D u[t - 1]``
        feedthrough).
    D : float
        Direct term of the sampled model (0: the reading at ``t`` never sees
        ``u[t]``).
    Ts : float
        Sample time, s.
    delay : int
        Sensor delay, samples.
    output : str
        Output name (e.g. ``'Bx_0'``).
    weights : ndarray, shape (n_coils,)
        Coil weights of the input (``x+ = u, x- = -u`` for the x pair).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: float
    Ts: float
    delay: int
    output: str
    weights: np.ndarray

    def freqresp(self, f: np.ndarray) -> np.ndarray:
        """Frequency response ``G(e^{j 2 pi f Ts})``, shape (nf,), complex (T/A).

        Parameters
        ----------
        f : array_like, shape (nf,)
            Frequencies, Hz.
        """
        f = np.atleast_1d(np.asarray(f, dtype=float))
        z = np.exp(2j * np.pi * f * self.Ts)
        n = self.A.shape[0]
        out = np.empty(f.shape, dtype=complex)
        for k, zk in enumerate(z):
            out[k] = self.C @ np.linalg.solve(zk * np.eye(n) - self.A, self.B) + self.D
        return out * z ** (-self.delay)

    def resonances(self, max_damping: float = RESONANCE_DAMPING) -> np.ndarray:
        """Frequencies (Hz) of the oscillatory poles with damping ratio below ``max_damping``.

        Parameters
        ----------
        max_damping : float
            Damping ratio (dimensionless) below which a pole pair counts as a resonance.

        Returns
        -------
        ndarray, shape (k,)
            Sorted, each pair counted once.
        """
        hz, damping = _oscillations(np.linalg.eigvals(self.A), self.Ts)
        # repeated poles (the symmetric x and y tilt modes) counted once
        return _once(hz[damping < max_damping])

    def antiresonances(self, max_damping: float = RESONANCE_DAMPING) -> np.ndarray:
        """Frequencies (Hz) of the oscillatory zeros with damping ratio below ``max_damping``.

        Where a direct term and the motion's response cancel (a board's pair
        feedthrough against the magnet's field), the response dips to nearly
        nothing: a notch, the mirror of a resonance.

        Parameters
        ----------
        max_damping : float
            Damping ratio (dimensionless) below which a zero pair counts.

        Returns
        -------
        ndarray, shape (k,)
            Sorted, each pair counted once.
        """
        from scipy.linalg import eigvals

        n = self.A.shape[0]
        rosenbrock = np.zeros((n + 1, n + 1))
        rosenbrock[:n, :n] = self.A
        rosenbrock[:n, n] = np.ravel(self.B)
        rosenbrock[n, :n] = np.ravel(self.C)
        rosenbrock[n, n] = float(np.ravel(self.D)[0]) if np.size(self.D) else 0.0
        pencil = np.zeros((n + 1, n + 1))
        pencil[:n, :n] = np.eye(n)
        with np.errstate(divide='ignore', invalid='ignore'):
            zeros = eigvals(rosenbrock, pencil)
        hz, damping = _oscillations(zeros[np.isfinite(zeros)], self.Ts)
        return _once(hz[np.abs(damping) < max_damping])

    def unstable_rates(self) -> np.ndarray:
        """Growth rates (1/s) of the unstable modes that show in this input-output path.

        A mode shows when the residue of its eigenspace, ``C P B`` (``P`` the
        spectral projector), is not nil. Modes of one growth rate (the
        symmetric x and y tilts) form one eigenspace and count once. Where the
        eigenvectors are too ill-conditioned to project on (condition number
        above 1e10), every unstable mode counts.

        Returns
        -------
        ndarray, shape (k,)
            Largest first (:func:`unstable_rates`).
        """
        w, V = np.linalg.eig(self.A)
        rates = _once(unstable_rates(w, self.Ts))
        if not rates.size or np.linalg.cond(V) > 1e10:
            return rates[::-1]
        Vinv = np.linalg.inv(V)
        scale = np.linalg.norm(self.C) * np.linalg.norm(self.B)
        growth = np.log(np.maximum(np.abs(w), 1e-300)) / self.Ts  # of every eigenvalue, 1/s
        upper = w.imag >= -1e-12 * np.abs(w)  # real, or the upper one of a complex pair
        shown = []
        for rate in rates:
            mode = (np.abs(growth - rate) <= 1e-6 * rate) & upper
            residue = self.C @ (V[:, mode] @ Vinv[mode, :]) @ self.B
            if abs(residue) > 1e-9 * scale:
                shown.append(rate)
        return np.array(shown[::-1])

    def impulse(self, n: int) -> np.ndarray:
        """First ``n`` samples of the response to a unit pulse ``u[0] = 1``.

        Parameters
        ----------
        n : int
            Number of samples.

        Returns
        -------
        ndarray, shape (n,)
            The pulse response (output units per input unit).
        """
        h = np.zeros(n)
        x = np.zeros(self.A.shape[0])
        for t in range(n):
            value = self.C @ x + (self.D if t == 0 else 0.0)
            if t + self.delay < n:
                h[t + self.delay] = value
            x = self.A @ x + (self.B if t == 0 else 0.0)
        return h


def _zoh(A: np.ndarray, B: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of ``dx = A x + B u``."""
    n, m = B.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n], block[:n, n:] = A * Ts, B * Ts
    E = expm(block)
    return E[:n, :n], E[:n, n:]


def local_plant(
    linear: object,
    Ts: float,
    output: str | int = 'Bx_0',
    pair: str | tuple[float, ...] = 'x',
    delay_samples: int = 1,
    coil_time_constant: float | None = None,
) -> LocalPlant:
    """Sample a linearisation into the true local SISO transfer function.

    Parameters
    ----------
    linear : physics.LinearModel
        Linearisation (``physics.linearize(model).reduced()``), with ``A``,
        ``B``, ``C``, ``D`` and the ``outputs`` names.
    Ts : float
        Sample time, s (the board: 2e-4).
    output : str or int
        Field component, by name (``'Bx_0'``: x field of sensor 0) or index.
    pair : {'x', 'y'} or sequence of float
        The input: an antisymmetric coil pair (``'x'``: x+ = u, x- = -u, as
        maglev-lab's ``u_x``) or explicit weights per coil.
    delay_samples : int
        Sensor delay, samples (default 1, the board's).
    coil_time_constant : float, optional
        ``L/R`` of the coils, s, when the simulation runs the coil dynamics
        with commanded currents (``CoilDynamics(drive='current')``); None for
        ideal coils (the input is the current).

    Returns
    -------
    LocalPlant
        The sampled model.

    Raises
    ------
    PhysicsCheckError
        Unknown output or pair, bad sample time, delay or time constant.
    """
    if not (np.isfinite(Ts) and Ts > 0):
        raise PhysicsCheckError(f'Ts must be a positive sample time in s, got {Ts!r}')
    if not isinstance(delay_samples, (int, np.integer)) or delay_samples < 0:
        raise PhysicsCheckError(f'delay_samples must be an integer >= 0, got {delay_samples!r}')
    A, B = np.asarray(linear.A, float), np.asarray(linear.B, float)
    C, D = np.asarray(linear.C, float), np.asarray(linear.D, float)
    names = list(getattr(linear, 'outputs', ()) or [])
    if isinstance(output, str):
        if output not in names:
            raise PhysicsCheckError(f'unknown output {output!r}; the model has {names}')
        row = names.index(output)
    else:
        row = int(output)
        if not 0 <= row < C.shape[0]:
            raise PhysicsCheckError(f'output index {output!r} out of range 0..{C.shape[0] - 1}')
        output = names[row] if names else f'y{row + 1}'
    if isinstance(pair, str):
        if pair not in PAIRS:
            raise PhysicsCheckError(f'unknown pair {pair!r}; choose {", ".join(PAIRS)}')
        w = np.zeros(B.shape[1])
        w[:4] = PAIRS[pair]
    else:
        w = np.asarray(pair, dtype=float)
        if w.shape != (B.shape[1],):
            raise PhysicsCheckError(
                f'pair weights must have {B.shape[1]} values (one per coil), got {w.shape}'
            )
    b, c, d = B @ w, C[row], float(D[row] @ w)
    n = A.shape[0]
    if coil_time_constant is None:
        Ad, Bd = _zoh(A, b[:, None], Ts)
        # state [x; u(t-1)]: the reading at t sees the current held since t-1
        Aa = np.zeros((n + 1, n + 1))
        Aa[:n, :n] = Ad
        Ba = np.zeros(n + 1)
        Ba[:n], Ba[n] = Bd[:, 0], 1.0
        Ca = np.concatenate([c, [d]])
        return LocalPlant(Aa, Ba, Ca, 0.0, float(Ts), int(delay_samples), str(output), w)
    tau = float(coil_time_constant)
    if not (np.isfinite(tau) and tau > 0):
        raise PhysicsCheckError(f'coil_time_constant must be positive (s), got {tau!r}')
    # current i of the pair as a state: di/dt = (u - i)/tau
    Ac = np.zeros((n + 1, n + 1))
    Ac[:n, :n], Ac[:n, n], Ac[n, n] = A, b, -1.0 / tau
    Bc = np.zeros((n + 1, 1))
    Bc[n, 0] = 1.0 / tau
    Ad, Bd = _zoh(Ac, Bc, Ts)
    Ca = np.concatenate([c, [d]])
    return LocalPlant(Ad, Bd[:, 0], Ca, 0.0, float(Ts), int(delay_samples), str(output), w)


@dataclass(frozen=True)
class FrequencyDeviation:
    """Deviation of an identified frequency response from the reference over a band.

    Attributes
    ----------
    frequencies : ndarray, shape (nf,)
        Evaluation frequencies, Hz.
    gain_db : ndarray, shape (nf,)
        ``20 log10 |G_id / G_true|``, dB.
    phase_deg : ndarray, shape (nf,)
        ``angle(G_id / G_true)`` wrapped to (-180, 180], degrees.
    max_db, rms_db : float
        Largest absolute and RMS gain deviation, dB.
    max_deg, rms_deg : float
        Largest absolute and RMS phase deviation, degrees.
    band : (float, float)
        The band asked for, Hz.
    excluded : tuple of float
        Resonances (Hz) of the reference whose neighbourhood was left out.
    notches : tuple of float
        Anti-resonances (Hz) of the reference whose neighbourhood was left out.
    uncertain : tuple of (float, float)
        Bands (Hz) left out where the reference itself is not known well
        enough (e.g. a notch that moves with a measured direct term).
    unstable_reference, unstable_model : tuple of float or None
        Growth rates (1/s) of the unstable modes of the reference (those that
        show in its path) and of the model (:func:`unstable_rates`); None
        where the system does not tell.
    """

    frequencies: np.ndarray
    gain_db: np.ndarray
    phase_deg: np.ndarray
    max_db: float
    rms_db: float
    max_deg: float
    rms_deg: float
    band: tuple[float, float] = (0.0, 0.0)
    excluded: tuple[float, ...] = ()
    notches: tuple[float, ...] = ()
    uncertain: tuple[tuple[float, float], ...] = ()
    unstable_reference: tuple[float, ...] | None = None
    unstable_model: tuple[float, ...] | None = None

    @property
    def misses_instability(self) -> bool:
        """Whether the model has fewer unstable modes than the reference shows in the band.

        A closed-loop estimate can put the mirrored, stable pole in place of
        the magnet's unstable one: the same gain, up to 180 degrees of phase
        below the mode's corner frequency ``rate / 2 pi``. Only the reference's
        modes whose corner lies in the band or above it count (V2's x mode, 30
        1/s or 4.8 Hz, does not for a 10-300 Hz check). More unstable poles than
        the reference are not flagged: where the phase agrees, zeros outside the
        unit circle cancel them. False where a system does not tell.
        """
        if self.unstable_reference is None or self.unstable_model is None:
            return False
        seen = [r for r in self.unstable_reference if r / (2 * np.pi) >= self.band[0]]
        return len(self.unstable_model) < len(seen)

    def within(self, db: float, deg: float) -> bool:
        """Return whether the gain stays within ``db`` dB and the phase within ``deg`` degrees.

        A model that misses an unstable mode of the reference
        (:attr:`misses_instability`) is not within, whatever its deviation.

        Parameters
        ----------
        db : float
            Largest allowed gain deviation, dB.
        deg : float
            Largest allowed phase deviation, degrees.

        Returns
        -------
        bool
        """
        return self.max_db <= db and self.max_deg <= deg and not self.misses_instability

    def instability(self) -> str:
        """Return the unstable modes, physics / model: ``'30 / 44 1/s'``, ``'30 / none 1/s'``."""
        if self.unstable_reference is None or self.unstable_model is None:
            return ''

        def rates(values: tuple[float, ...]) -> str:
            return ', '.join(f'{v:.0f}' for v in values) if values else 'none'

        return f'{rates(self.unstable_reference)} / {rates(self.unstable_model)} 1/s'

    def brief(self) -> str:
        """Return the table cell: largest deviation, and a missed unstable mode if one is."""
        text = f'{self.max_db:5.2f} dB {self.max_deg:5.1f} deg'
        return text + (' (no unstable pole)' if self.misses_instability else '')

    def summary(self) -> str:
        """One line: band, max and RMS deviation."""
        low, high = self.band if self.band[1] else self.frequencies[[0, -1]]
        text = (
            f'{low:g}-{high:g} Hz: max {self.max_db:.2f} dB / {self.max_deg:.1f} deg, '
            f'rms {self.rms_db:.2f} dB / {self.rms_deg:.1f} deg'
        )
        if self.excluded:
            text += ' (without +-{:g} Hz around the undamped resonance(s) at {} Hz)'.format(
                RESONANCE_WIDTH, ', '.join(f'{f:.2f}' for f in self.excluded)
            )
        if self.notches:
            text += ' (without +-{:g} Hz around the notch(es) at {} Hz)'.format(
                RESONANCE_WIDTH, ', '.join(f'{f:.2f}' for f in self.notches)
            )
        if self.uncertain:
            text += ' (without {} Hz, where the reference is a near-cancellation)'.format(
                ', '.join(f'{lo:.2f}-{hi:.2f}' for lo, hi in self.uncertain)
            )
        if self.misses_instability:
            text += f'; the model misses an unstable mode (physics / model: {self.instability()})'
        return text


def compare_response(
    model: object,
    reference: object,
    band: tuple[float, float],
    n: int = 200,
    output: int = 0,
    input: int = 0,  # noqa: A002 - the toolbox's name
    resonance_width: float = RESONANCE_WIDTH,
    uncertain: Sequence[tuple[float, float]] = (),
) -> FrequencyDeviation:
    """Compare the frequency response of ``model`` with ``reference`` over a band.

    Near an undamped (or very lightly damped) resonance of the reference its
    response is unbounded, and no estimate from finite data follows it: the
    frequencies within ``resonance_width`` of each resonance of a
    :class:`LocalPlant` reference (damping ratio below
    :data:`RESONANCE_DAMPING`; the linearised magnet has undamped tilt modes)
    are left out and listed in the result (modes that cancel in this path,
    e.g. the z or y tilt modes seen from the x input, are kept). Likewise
    around each notch (a zero pair of the same damping that shows in the
    response, where a direct term cancels the motion's response): there the
    reference falls to nearly nothing and any estimate's ratio to it is
    unbounded (listed as ``notches``).

    Parameters
    ----------
    model : PolyModel or LocalPlant
        Anything with ``freqresp(f)``; a (nf, ny, nu) response is reduced to
        ``[:, output, input]``.
    reference : LocalPlant or PolyModel
        The true response (same convention).
    band : (float, float)
        Lowest and highest frequency, Hz (0 < low < high).
    n : int
        Number of log-spaced frequencies (>= 2).
    output, input : int
        Channel of a MIMO model.
    resonance_width : float
        Half-width of the band left out around each resonance, Hz (0: none).
    uncertain : sequence of (float, float)
        Bands (Hz) where the reference is not known well enough to compare
        (left out and listed; e.g.
        :func:`~maglev_ros.sysid.board_check.cancellation_bands`).

    Returns
    -------
    FrequencyDeviation
        Gain (dB) and phase (degrees) deviation, max and RMS, and the unstable
        modes of both (:attr:`FrequencyDeviation.misses_instability`).

    Raises
    ------
    PhysicsCheckError
        Bad band or count, a band that is all resonance, or a reference with
        zero response in the band.
    """
    low, high = (float(v) for v in band)
    if not (0 < low < high):
        raise PhysicsCheckError(f'band must be 0 < low < high in Hz, got {band!r}')
    if int(n) < 2:
        raise PhysicsCheckError(f'n must be at least 2 frequencies, got {n!r}')
    f = np.geomspace(low, high, int(n))
    excluded: list[float] = []
    notches: list[float] = []
    if resonance_width > 0:
        for listed, method in ((excluded, 'resonances'), (notches, 'antiresonances')):
            for fr in _showing(reference, method):
                if low - resonance_width <= fr <= high + resonance_width:
                    listed.append(fr)
                f = f[np.abs(f - fr) > resonance_width]
    kept_out = []
    for lo, hi in uncertain:
        if hi >= low and lo <= high:
            kept_out.append((float(lo), float(hi)))
        f = f[(f < lo) | (f > hi)]
    if f.size < 2:
        raise PhysicsCheckError(
            f'band {band!r} lies within {resonance_width} Hz of resonances {excluded}'
            + (f' and notches {notches}' if notches else '')
            + (f' and uncertain bands {kept_out}' if kept_out else '')
            + ': nothing left to compare'
        )

    def response(system: object) -> np.ndarray:
        g = np.asarray(system.freqresp(f))
        return g[:, output, input] if g.ndim == 3 else g

    g_true = response(reference)
    if np.any(g_true == 0):
        raise PhysicsCheckError('the reference response is zero in the band: nothing to compare')
    ratio = response(model) / g_true
    with np.errstate(divide='ignore'):
        gain = 20.0 * np.log10(np.abs(ratio))
    phase = np.degrees(np.angle(ratio))
    return FrequencyDeviation(
        frequencies=f,
        gain_db=gain,
        phase_deg=phase,
        max_db=float(np.max(np.abs(gain))),
        rms_db=float(np.sqrt(np.mean(gain**2))),
        max_deg=float(np.max(np.abs(phase))),
        rms_deg=float(np.sqrt(np.mean(phase**2))),
        band=(low, high),
        excluded=tuple(excluded),
        notches=tuple(notches),
        uncertain=tuple(kept_out),
        unstable_reference=_unstable(reference),
        unstable_model=_unstable(model),
    )


def _showing(reference: object, method: str) -> list[float]:
    """Resonances or notches (Hz) of a reference that show in its input-output path.

    A mode or a zero pair cancelled in this path (the y tilt seen from the x
    pair) does not show: a resonance shows where the response near it is at
    least twice its largest 0.5 Hz away, a notch where it is at most half the
    smallest.

    Parameters
    ----------
    reference : LocalPlant
        Anything with ``freqresp`` and the method.
    method : {'resonances', 'antiresonances'}
        Which: the lightly damped poles or zeros (:meth:`LocalPlant.resonances`).

    Returns
    -------
    list of float
        Frequencies, Hz, ascending (empty for a reference without the method).
    """
    shows = {
        'resonances': lambda close, apart: close.max() >= 2.0 * apart.max(),
        'antiresonances': lambda close, apart: close.min() <= 0.5 * apart.min(),
    }[method]
    out = []
    for fr in getattr(reference, method, lambda: ())():
        close = np.abs(reference.freqresp(fr * np.array([1 - 1e-5, 1 + 1e-5])))
        apart = np.abs(reference.freqresp(np.array([fr - 0.5, fr + 0.5])))
        if shows(close, apart):
            out.append(float(fr))
    return out


def _unstable(system: object) -> tuple[float, ...] | None:
    """Growth rates (1/s) of a system's unstable modes, or None if it does not tell."""
    if hasattr(system, 'unstable_rates'):
        return tuple(float(r) for r in system.unstable_rates())
    if hasattr(system, 'poles') and getattr(system, 'Ts', None):
        return tuple(float(r) for r in unstable_rates(system.poles(), system.Ts))
    return None


def _oscillations(roots: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequency (Hz) and damping ratio of each oscillatory root of the z-plane (one per pair)."""
    roots = roots[(np.abs(roots) > 0) & (roots.imag > 0)]
    s = np.log(roots) / Ts  # continuous-time equivalents, 1/s
    return np.abs(s) / (2 * np.pi), -s.real / np.abs(s)


def _once(hz: np.ndarray) -> np.ndarray:
    """Sorted frequencies, repeated ones (within 1e-6 of each other) counted once."""
    found = np.sort(hz)
    keep = np.r_[True, np.diff(found) > 1e-6 * np.maximum(found[1:], 1e-300)]
    return found[keep] if found.size else found
