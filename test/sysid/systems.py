"""Data simulated from known systems, written independently of the package (lfilter)."""

import numpy as np
from scipy.signal import lfilter

from maglev_ros.sysid import IdData

TS = 2e-4

# SISO systems, polynomials in q^-1 (B with its nk leading zeros).
A2 = np.array([1.0, -1.5, 0.7])
B2 = np.array([0.0, 1.0, 0.5])
C_COLORED = np.array([1.0, -1.2, 0.5])  # strongly colored MA noise
C_ARMAX = np.array([1.0, 0.5])
F_OE = np.array([1.0, -1.2, 0.5])
C_BJ = np.array([1.0, 0.4])
D_BJ = np.array([1.0, -0.85])


def simulate_siso(N, seed, A=A2, B=B2, C=(1.0,), D=(1.0,), F=(1.0,), noise=0.2, u_std=1.0):
    """y = B/(A F) u + C/(A D) e with white Gaussian u and e."""
    rng = np.random.default_rng(seed)
    u = u_std * rng.standard_normal(N)
    e = noise * rng.standard_normal(N)
    y = lfilter(B, np.convolve(A, F), u) + lfilter(C, np.convolve(A, D), e)
    return IdData(y, u, TS)


# 2x2 MIMO ARX with na=[4 4;0 4], nb=[2 2;0 2], nk=[1 1;1 1] (lab structure).
MIMO_A11 = np.poly([0.9, 0.8, 0.5 + 0.3j, 0.5 - 0.3j]).real
MIMO_A22 = np.poly([0.85, 0.6, -0.3, 0.2]).real
MIMO_A12 = np.array([0.0, 0.3, -0.2, 0.1, 0.05])
MIMO_B11 = np.array([0.0, 1.0, 0.4])
MIMO_B12 = np.array([0.0, 0.5, -0.3])
MIMO_B22 = np.array([0.0, 0.8, 0.2])


def mimo_arx_truth():
    """True parameter vector in the package layout (row 1: A11 A12 B11 B12; row 2: A22 B22)."""
    return np.concatenate(
        [MIMO_A11[1:], MIMO_A12[1:], MIMO_B11[1:], MIMO_B12[1:], MIMO_A22[1:], MIMO_B22[1:]]
    )


def simulate_mimo_arx(N, seed, noise=0.1):
    """A y = B u + e for the lab structure; A21 = 0 so y2 can be simulated first."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((N, 2))
    e = noise * rng.standard_normal((N, 2))
    y2 = lfilter(MIMO_B22, MIMO_A22, u[:, 1]) + lfilter([1.0], MIMO_A22, e[:, 1])
    rhs = (
        lfilter(MIMO_B11, [1.0], u[:, 0])
        + lfilter(MIMO_B12, [1.0], u[:, 1])
        - lfilter(MIMO_A12, [1.0], y2)
        + e[:, 0]
    )
    y1 = lfilter([1.0], MIMO_A11, rhs)
    return IdData(np.column_stack([y1, y2]), u, TS)


# 2x2 MIMO ARMAX with na=[2 2;0 2], nb=[1 1;0 1], nc=[1;1], nk=1 (lab structure).
MA_A11 = np.array([1.0, -1.4, 0.6])
MA_A12 = np.array([0.0, 0.4, -0.2])
MA_A22 = np.array([1.0, -1.1, 0.3])
MA_B11 = np.array([0.0, 1.0])
MA_B12 = np.array([0.0, 0.5])
MA_B22 = np.array([0.0, 0.7])
MA_C1 = np.array([1.0, 0.6])
MA_C2 = np.array([1.0, -0.5])


def mimo_armax_truth():
    """Row 1: A11 A12 B11 B12 C1; row 2: A22 B22 C2."""
    return np.concatenate(
        [
            MA_A11[1:],
            MA_A12[1:],
            MA_B11[1:],
            MA_B12[1:],
            MA_C1[1:],
            MA_A22[1:],
            MA_B22[1:],
            MA_C2[1:],
        ]
    )


def simulate_mimo_armax(N, seed, noise=0.3):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((N, 2))
    e = noise * rng.standard_normal((N, 2))
    y2 = lfilter(MA_B22, MA_A22, u[:, 1]) + lfilter(MA_C2, MA_A22, e[:, 1])
    rhs = (
        lfilter(MA_B11, [1.0], u[:, 0])
        + lfilter(MA_B12, [1.0], u[:, 1])
        - lfilter(MA_A12, [1.0], y2)
        + lfilter(MA_C1, [1.0], e[:, 0])
    )
    y1 = lfilter([1.0], MA_A11, rhs)
    return IdData(np.column_stack([y1, y2]), u, TS)


def mean_error(estimate, sizes, seeds, truth):
    """Mean parameter-error norm over seeds, for each data length."""
    return np.array(
        [np.mean([np.linalg.norm(estimate(N, s) - truth) for s in seeds]) for N in sizes]
    )


def lab_second_order(N=25000, seed=0, offset=1.2e-3, noise=1e-6):
    """The lab's data shape: a field (T) that is a 2nd-order response to a PRBS coil input (A).

    PRBS of +-0.5 A held for 5 samples, poles 0.95 +- 0.1j, about 2 mT/A of DC
    gain, an offset and white sensor noise; a student's lower-order board. Returns
    the raw (not detrended) data.
    """
    rng = np.random.default_rng(seed)
    u = 0.5 * np.repeat(rng.integers(0, 2, N // 5 + 1) * 2.0 - 1.0, 5)[:N]
    a = np.poly([0.95 + 0.1j, 0.95 - 0.1j]).real
    b = np.array([0.0, 2.5e-5, 2e-5])
    y = lfilter(b, a, u) + offset + noise * rng.standard_normal(N)
    return IdData(y, u, TS, ['Bx'], ['Ix'], ['T'], ['A'])
