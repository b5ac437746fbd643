"""Excitation signals for system identification (MATLAB ``idinput`` conventions).

Every generator returns ``length`` samples of one channel with values in
``[-amplitude, amplitude]``; ``band = (low, high)`` is a pass band as fractions
of the Nyquist frequency. Random choices come from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal as sps

__all__ = ['SIGNALS', 'chirp', 'excitation', 'multisine', 'prbs', 'random_binary']

SIGNALS = ('prbs', 'random_binary', 'multisine', 'chirp')

# Feedback taps of maximum-length LFSRs (Fibonacci form), register length: taps.
_LFSR_TAPS = {
    2: (2, 1),
    3: (3, 2),
    4: (4, 3),
    5: (5, 3),
    6: (6, 5),
    7: (7, 6),
    8: (8, 6, 5, 4),
    9: (9, 5),
    10: (10, 7),
    11: (11, 9),
    12: (12, 6, 4, 1),
    13: (13, 4, 3, 1),
    14: (14, 5, 3, 1),
    15: (15, 14),
    16: (16, 15, 13, 4),
    17: (17, 14),
    18: (18, 11),
    19: (19, 6, 2, 1),
    20: (20, 17),
}


def _check(length: int, amplitude: float, band: tuple[float, float]) -> tuple[float, float]:
    if not isinstance(length, (int, np.integer)) or length < 1:
        raise ValueError(f'length must be an integer >= 1, got {length!r}')
    if not (math.isfinite(amplitude) and amplitude >= 0):
        raise ValueError(f'amplitude must be a finite number >= 0, got {amplitude!r}')
    low, high = (float(b) for b in band)
    if not (0.0 <= low < high <= 1.0):
        raise ValueError(
            f'band must be (low, high) with 0 <= low < high <= 1 (fractions of '
            f'Nyquist), got {tuple(band)!r}'
        )
    return low, high


def prbs(
    length: int,
    amplitude: float = 1.0,
    band: tuple[float, float] = (0.0, 1.0),
    seed: int | None = 0,
    order: int | None = None,
) -> np.ndarray:
    """Maximum-length pseudo-random binary sequence.

    Parameters
    ----------
    length : int
        Samples.
    amplitude : float
        Output levels are +-amplitude.
    band : (float, float)
        ``(0, high)``: each bit is held for ``round(1 / high)`` samples (the
        ``idinput`` clock period); a PRBS has no lower band edge, so ``low``
        must be 0.
    seed : int or None
        Chooses the (non-zero) initial register state.
    order : int, optional
        Register length in 2 .. 20 (default: the smallest whose period
        ``2**order - 1`` bits covers ``length``, capped at 20).

    Returns
    -------
    ndarray, shape (length,)
    """
    low, high = _check(length, amplitude, band)
    if low != 0.0:
        raise ValueError(f'band of a prbs must start at 0, got {tuple(band)!r}')
    hold = max(int(round(1.0 / high)), 1)
    bits_needed = -(-length // hold)
    if order is None:
        order = min(max(int(math.ceil(math.log2(bits_needed + 1))), 2), 20)
    if order not in _LFSR_TAPS:
        raise ValueError(f'order must be in 2 .. 20, got {order!r}')
    taps = _LFSR_TAPS[order]
    rng = np.random.default_rng(seed)
    state = int(rng.integers(1, 2**order))
    bits = np.empty(bits_needed, dtype=np.int8)
    for i in range(bits_needed):
        bits[i] = state & 1
        feedback = 0
        for t in taps:
            feedback ^= (state >> (order - t)) & 1
        state = (state >> 1) | (feedback << (order - 1))
    out = np.repeat(2.0 * bits - 1.0, hold)[:length]
    return amplitude * out


def random_binary(
    length: int,
    amplitude: float = 1.0,
    band: tuple[float, float] = (0.0, 1.0),
    seed: int | None = 0,
) -> np.ndarray:
    """Random binary signal: the sign of band-limited Gaussian noise (as ``idinput('rbs')``).

    Parameters
    ----------
    length : int
        Samples.
    amplitude : float
        Output levels are +-amplitude.
    band : (float, float)
        Pass band of the noise before the sign, fractions of Nyquist.
    seed : int or None
        Noise seed.

    Returns
    -------
    ndarray, shape (length,)
    """
    low, high = _check(length, amplitude, band)
    noise = np.random.default_rng(seed).standard_normal(length)
    if (low, high) != (0.0, 1.0):
        if low == 0.0:
            sos = sps.butter(8, high, 'lowpass', output='sos')
        elif high == 1.0:
            sos = sps.butter(8, low, 'highpass', output='sos')
        else:
            sos = sps.butter(8, (low, high), 'bandpass', output='sos')
        noise = sps.sosfilt(sos, noise)
    out = np.where(noise >= 0.0, 1.0, -1.0)
    return amplitude * out


def multisine(
    length: int,
    amplitude: float = 1.0,
    band: tuple[float, float] = (0.0, 1.0),
    seed: int | None = 0,
    n_sines: int | None = None,
) -> np.ndarray:
    """Periodic sum of sinusoids on the DFT grid of ``length``, random phases.

    Parameters
    ----------
    length : int
        Samples: one period (frequencies ``k / length`` cycles per sample).
    amplitude : float
        Peak of the output (scaled so that max |u| = amplitude).
    band : (float, float)
        Frequencies used, fractions of Nyquist (at least one grid line).
    seed : int or None
        Phase seed.
    n_sines : int, optional
        Use only this many grid lines of the band, evenly spread (default all).

    Returns
    -------
    ndarray, shape (length,)
    """
    low, high = _check(length, amplitude, band)
    k = np.arange(1, length // 2 + 1)
    nyquist_fraction = 2.0 * k / length
    lines = k[(nyquist_fraction >= low) & (nyquist_fraction <= high)]
    if lines.size == 0:
        raise ValueError(f'band {tuple(band)!r} holds no frequency of a {length}-sample period')
    if n_sines is not None:
        if n_sines < 1:
            raise ValueError(f'n_sines must be >= 1, got {n_sines!r}')
        lines = lines[np.unique(np.linspace(0, lines.size - 1, n_sines).round().astype(int))]
    phases = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, lines.size)
    t = np.arange(length)
    out = np.cos(2.0 * np.pi * np.outer(t, lines) / length + phases).sum(axis=1)
    peak = np.abs(out).max()
    return amplitude * out / peak if peak > 0 else out


def chirp(
    length: int,
    amplitude: float = 1.0,
    band: tuple[float, float] = (0.0, 1.0),
    seed: int | None = 0,
) -> np.ndarray:
    """Linear frequency sweep from ``band[0]`` to ``band[1]`` (x Nyquist) over ``length``.

    Parameters
    ----------
    length : int
        Samples.
    amplitude : float
        Peak.
    band : (float, float)
        Start and end frequency, fractions of Nyquist.
    seed : int or None
        Unused (deterministic signal; accepted for a uniform interface).

    Returns
    -------
    ndarray, shape (length,)
    """
    low, high = _check(length, amplitude, band)
    t = np.arange(length, dtype=float)
    end = max(length - 1, 1)
    return amplitude * sps.chirp(t, f0=low / 2.0, t1=end, f1=high / 2.0, method='linear')


_GENERATORS = {
    'prbs': prbs,
    'random_binary': random_binary,
    'multisine': multisine,
    'chirp': chirp,
}


def excitation(
    kind: str,
    length: int,
    channels: int = 1,
    amplitude: float = 1.0,
    band: tuple[float, float] = (0.0, 1.0),
    seed: int = 0,
) -> np.ndarray:
    """Independent excitation signals, one per channel.

    Parameters
    ----------
    kind : {'prbs', 'random_binary', 'multisine', 'chirp'}
        Signal type.
    length : int
        Samples per channel.
    channels : int
        Number of independent channels (channel j uses a seed derived from
        ``seed`` and j; a chirp is delayed by ``j * length // channels``).
    amplitude : float
        Peak per channel.
    band : (float, float)
        Band, fractions of Nyquist.
    seed : int
        Base seed.

    Returns
    -------
    ndarray, shape (length, channels)
    """
    if kind not in _GENERATORS:
        raise ValueError(f'signal must be one of {", ".join(SIGNALS)}, got {kind!r}')
    if not isinstance(channels, (int, np.integer)) or channels < 1:
        raise ValueError(f'channels must be an integer >= 1, got {channels!r}')
    seeds = np.random.SeedSequence(seed).generate_state(channels)
    columns = []
    for j in range(channels):
        u = _GENERATORS[kind](length, amplitude, band, seed=int(seeds[j]))
        if kind == 'chirp':
            u = np.roll(u, j * length // channels)
        columns.append(u)
    return np.column_stack(columns)
