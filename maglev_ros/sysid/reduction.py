"""Balanced truncation of identified models: Hankel singular values, reduced order, checks.

Square-root balanced truncation for discrete time (Laub et al. 1987; Antoulas,
*Approximation of Large-Scale Dynamical Systems*, 2005, sec. 7.2), written
with scipy:

1. The model's state space (:meth:`PolyModel.to_ss`) is split by an ordered
   real Schur form and a Sylvester equation into its stable part (poles
   inside the unit circle) and its unstable part (on or outside).  The
   unstable part is **kept whole**: balancing needs finite Gramians, and the
   unstable modes are the ones a controller must see.
2. For the stable part, the discrete Gramians ``P = A P A' + B B'`` and
   ``Q = A' Q A + C' C`` (``scipy.linalg.solve_discrete_lyapunov``) are
   factored ``P = R R'``, ``Q = L L'``; the SVD ``L' R = U S V'`` gives the
   Hankel singular values ``S``, and the projections
   ``T = R V_r S_r^-1/2``, ``W = L U_r S_r^-1/2`` the reduced stable part
   ``(W' A T, W' B, C T)``.  The feedthrough ``D`` is kept.

The order is given, or chosen as the smallest one whose Hankel singular
values keep a stated fraction (default 99 %) of their sum.  The error bound
``|G - G_r|_inf <= 2 sum(discarded S)`` holds for the stable part.

Why not python-control's ``balred``: it needs slycot, and python-control
0.10's ``balred`` passes ``dico='C'`` to SLICOT for every system (a
discrete model's poles would be judged as continuous-time ones).  Installing
slycot also routes python-control's ``dlqr`` through SLICOT, which rejects
the controller design of this package; so slycot is not a dependency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

from .criteria import fit_percent
from .dataset import IdData
from .model import PolyModel
from .polynomial import free_response, simulate_ss

__all__ = [
    'DEFAULT_FRACTION',
    'Reduction',
    'StateSpaceModel',
    'balanced_truncation',
    'hankel_singular_values',
]

DEFAULT_FRACTION = 0.99


@dataclass(frozen=True, eq=False)
class StateSpaceModel:
    """A discrete-time state-space model ``x+ = A x + B u``, ``y = C x + D u``.

    Parameters
    ----------
    A, B, C, D : ndarray
        Shapes (n, n), (n, nu), (ny, n), (ny, nu).
    Ts : float
        Sample time in seconds.
    output_names, input_names : tuple of str
        Channel labels.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    Ts: float
    output_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()

    @property
    def order(self) -> int:
        """Number of states."""
        return int(self.A.shape[0])

    @property
    def ny(self) -> int:
        """Number of outputs."""
        return int(self.C.shape[0])

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return int(self.B.shape[1])

    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A`` (z-plane)."""
        return np.linalg.eigvals(self.A)

    def freqresp(self, f: np.ndarray) -> np.ndarray:
        """Frequency response at ``f`` Hz, shape (nf, ny, nu), complex.

        Parameters
        ----------
        f : array_like, shape (nf,)
            Frequencies in Hz (a scalar is one frequency).
        """
        f = np.atleast_1d(np.asarray(f, dtype=float))
        z = np.exp(2j * np.pi * f * self.Ts)
        eye = np.eye(self.order)
        return np.array(
            [self.C @ np.linalg.solve(zk * eye - self.A, self.B) + self.D for zk in z]
        ).reshape(len(f), self.ny, self.nu)

    def simulate(self, data: IdData | np.ndarray, ic: str = 'zero') -> np.ndarray:
        """Simulate the outputs, shape (N, ny); ``ic='estimate'`` fits ``x0`` to ``data.y``.

        Parameters
        ----------
        data : IdData or ndarray, shape (N, nu)
            Inputs (IdData with measured outputs for ``ic='estimate'``).
        ic : {'zero', 'estimate'}
            Initial state: zero, or the least-squares fit to the measured outputs.
        """
        u = data.u if isinstance(data, IdData) else np.asarray(data, dtype=float)
        u = np.ascontiguousarray(u.reshape(u.shape[0], -1))
        if self.order == 0:
            return u @ self.D.T
        y = simulate_ss(self.A, self.B, self.C, self.D, np.zeros(self.order), u)
        if ic == 'zero':
            return y
        if not isinstance(data, IdData):
            raise TypeError("ic='estimate' needs IdData with measured outputs")
        basis = free_response(self.A, self.C, u.shape[0]).reshape(-1, self.order)
        x0 = np.linalg.lstsq(basis, (data.y - y).ravel(), rcond=None)[0]
        return y + (basis @ x0).reshape(y.shape)


def _split_stable(
    A: np.ndarray, B: np.ndarray, C: np.ndarray
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """Return ``(As, Bs, Cs), (Au, Bu, Cu)``: stable and unstable parts, block-diagonal."""
    T, Z, n_stable = linalg.schur(A, output='real', sort=lambda re, im: re * re + im * im < 1.0)
    B1 = Z.T @ B
    C1 = C @ Z
    s = n_stable
    if 0 < s < A.shape[0]:
        X = linalg.solve_sylvester(T[:s, :s], -T[s:, s:], -T[:s, s:])
        # S = [[I, X], [0, I]]: S^-1 T S is block diagonal
        B1 = np.vstack([B1[:s] - X @ B1[s:], B1[s:]])
        C1 = np.hstack([C1[:, :s], C1[:, :s] @ X + C1[:, s:]])
    return (T[:s, :s], B1[:s], C1[:, :s]), (T[s:, s:], B1[s:], C1[:, s:])


def _sqrt_factor(G: np.ndarray) -> np.ndarray:
    """``R`` with ``R R' = G`` for a symmetric positive semidefinite ``G``."""
    w, V = np.linalg.eigh(0.5 * (G + G.T))
    return V * np.sqrt(np.clip(w, 0.0, None))


def _balance(As: np.ndarray, Bs: np.ndarray, Cs: np.ndarray) -> tuple[np.ndarray, ...]:
    P = linalg.solve_discrete_lyapunov(As, Bs @ Bs.T)
    Q = linalg.solve_discrete_lyapunov(As.T, Cs.T @ Cs)
    R, L = _sqrt_factor(P), _sqrt_factor(Q)
    U, hsv, Vt = np.linalg.svd(L.T @ R)
    return hsv, U, Vt.T, R, L


def hankel_singular_values(model: PolyModel | StateSpaceModel) -> tuple[np.ndarray, int]:
    """Hankel singular values of the stable part, and the number of unstable poles.

    Parameters
    ----------
    model : PolyModel or StateSpaceModel
        A discrete-time model.

    Returns
    -------
    hsv : ndarray, shape (n_stable,)
        Descending.
    n_unstable : int
        Poles on or outside the unit circle (kept whole by the reduction).
    """
    ss = _as_ss(model)
    (As, Bs, Cs), (Au, _, _) = _split_stable(ss.A, ss.B, ss.C)
    hsv = _balance(As, Bs, Cs)[0] if As.shape[0] else np.zeros(0)
    return hsv, int(Au.shape[0])


def _as_ss(model: PolyModel | StateSpaceModel) -> StateSpaceModel:
    if isinstance(model, StateSpaceModel):
        return model
    A, B, C, D, _ = model.innovations_form()
    A, B, C, D = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, C, D))
    return StateSpaceModel(
        A, B[:, : model.nu], C, D[:, : model.nu], model.Ts, model.output_names, model.input_names
    )


@dataclass(frozen=True)
class Reduction:
    """Outcome of :func:`balanced_truncation`.

    Attributes
    ----------
    full, reduced : StateSpaceModel
        The model before and after.
    hsv : ndarray
        Hankel singular values of the stable part, descending.
    kept : int
        Stable states kept.
    n_unstable : int
        Unstable states, all kept.
    fraction : float
        Share of the sum of the Hankel singular values kept.
    error_bound : float
        ``2 sum(discarded hsv)``: bound of the largest gain error.
    """

    full: StateSpaceModel
    reduced: StateSpaceModel
    hsv: np.ndarray
    kept: int
    n_unstable: int
    fraction: float
    error_bound: float

    @property
    def order(self) -> int:
        """Order of the reduced model (stable kept + unstable)."""
        return self.reduced.order

    def fit_loss(self, data: IdData, ic: str = 'estimate') -> tuple[np.ndarray, np.ndarray]:
        """Return the simulation fits (percent, per output) of the full and the reduced model.

        Parameters
        ----------
        data : IdData
            Validation data (measured inputs and outputs).
        ic : {'estimate', 'zero'}
            Initial state of the simulations, as :meth:`StateSpaceModel.simulate`.
        """
        return (
            fit_percent(data.y, self.full.simulate(data, ic)),
            fit_percent(data.y, self.reduced.simulate(data, ic)),
        )

    def summary(self) -> str:
        """One line: orders, fraction kept, error bound."""
        return (
            f'balanced truncation: order {self.full.order} -> {self.order} '
            f'({self.kept} stable states kept of {len(self.hsv)}, {self.n_unstable} unstable '
            f'kept whole); Hankel singular values kept {100 * self.fraction:.3f} %, '
            f'gain error bound {self.error_bound:.3g}'
        )


def balanced_truncation(
    model: PolyModel | StateSpaceModel,
    order: int | None = None,
    fraction: float = DEFAULT_FRACTION,
) -> Reduction:
    """Reduce a model by square-root balanced truncation (unstable part kept whole).

    Parameters
    ----------
    model : PolyModel or StateSpaceModel
        Discrete-time model.
    order : int, optional
        Total order of the reduced model (unstable states included).
    fraction : float
        Without ``order``: keep the fewest stable states whose Hankel singular
        values make up at least this share of their sum (0 < fraction <= 1).

    Returns
    -------
    Reduction
        Reduced model, Hankel singular values and error bound.
    """
    full = _as_ss(model)
    (As, Bs, Cs), (Au, Bu, Cu) = _split_stable(full.A, full.B, full.C)
    n_unstable = Au.shape[0]
    if As.shape[0]:
        hsv, U, V, R, L = _balance(As, Bs, Cs)
    else:
        hsv = np.zeros(0)
    total = float(hsv.sum())
    if order is None:
        if not 0.0 < fraction <= 1.0:
            raise ValueError(f'fraction must be in (0, 1], got {fraction!r}')
        share = np.cumsum(hsv) / total if total > 0 else np.ones(len(hsv))
        kept = int(np.searchsorted(share, fraction - 1e-12) + 1) if len(hsv) else 0
    else:
        if not n_unstable <= int(order) <= full.order:
            raise ValueError(
                f'order must be from {n_unstable} (the unstable states, kept whole) '
                f'to {full.order}, got {order!r}'
            )
        kept = int(order) - n_unstable
    kept = min(kept, int(np.sum(hsv > 1e-14 * max(total, 1e-300))) or kept)
    if kept:
        scale = 1.0 / np.sqrt(hsv[:kept])
        T = R @ V[:, :kept] * scale
        W = L @ U[:, :kept] * scale
        Ar, Br, Cr = W.T @ As @ T, W.T @ Bs, Cs @ T
    else:
        Ar, Br, Cr = np.zeros((0, 0)), np.zeros((0, full.nu)), np.zeros((full.ny, 0))
    reduced = StateSpaceModel(
        linalg.block_diag(Ar, Au),
        np.vstack([Br, Bu]),
        np.hstack([Cr, Cu]),
        full.D,
        full.Ts,
        full.output_names,
        full.input_names,
    )
    return Reduction(
        full=full,
        reduced=reduced,
        hsv=hsv,
        kept=kept,
        n_unstable=n_unstable,
        fraction=float(hsv[:kept].sum() / total) if total > 0 else 1.0,
        error_bound=float(2 * hsv[kept:].sum()),
    )
