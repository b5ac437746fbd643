"""Linearisation of the Maggy model and its reduced 10-state form."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import matrix_balance

from ..topics import COIL_NAMES
from .model import STATE_NAMES

__all__ = [
    'FD_STEP',
    'REDUCED_STATES',
    'LinearModel',
    'linearize',
    'controllability_rank',
    'observability_rank',
    'input_names',
    'output_names',
]

#: Central finite-difference step, in the state's and input's own units (m, rad,
#: m/s, rad/s, A). The fields are smooth (no axis cut-off), so the Jacobians
#: agree between 1e-6 and 1e-4 steps to better than 1e-3.
FD_STEP = 1e-6
#: The states kept in the reduced model: yaw (gamma) and yaw rate (wz) are
#: neither controllable nor observable with axisymmetric magnets.
REDUCED_STATES = tuple(i for i, name in enumerate(STATE_NAMES) if name not in ('gamma', 'wz'))


def input_names(n_inputs: int) -> tuple[str, ...]:
    """Solenoid names in the package's order (x+, x-, y+, y-, then s4, s5, ...)."""
    return tuple(COIL_NAMES[j] if j < 4 else f's{j}' for j in range(n_inputs))


def output_names(n_sensors: int) -> tuple[str, ...]:
    """Measurement names: Bx_0, By_0, Bz_0, Bx_1, ... (tesla)."""
    return tuple(f'B{axis}_{k}' for k in range(n_sensors) for axis in 'xyz')


@dataclass(frozen=True)
class LinearModel:
    """Continuous-time linearisation dx = A dx + B du, dy = C dx + D du.

    Attributes
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    C : ndarray, shape (p, n)
    D : ndarray, shape (p, m)
    x_eq : ndarray, shape (12,)
        Linearisation state.
    u_eq : ndarray, shape (m,)
        Linearisation input, A.
    y_eq : ndarray, shape (p,)
        Output at the linearisation point, T.
    states, inputs, outputs : tuple of str
        Names, in order.
    step : float
        Finite-difference step used.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    x_eq: np.ndarray
    u_eq: np.ndarray
    y_eq: np.ndarray
    states: tuple[str, ...] = STATE_NAMES
    inputs: tuple[str, ...] = field(default_factory=tuple)
    outputs: tuple[str, ...] = field(default_factory=tuple)
    step: float = FD_STEP

    def reduced(self) -> LinearModel:
        """Return the 10-state model without yaw (gamma) and yaw rate (wz)."""
        keep = [i for i, name in enumerate(self.states) if name not in ('gamma', 'wz')]
        return LinearModel(
            A=self.A[np.ix_(keep, keep)],
            B=self.B[keep],
            C=self.C[:, keep],
            D=self.D,
            x_eq=self.x_eq,
            u_eq=self.u_eq,
            y_eq=self.y_eq,
            states=tuple(self.states[i] for i in keep),
            inputs=self.inputs,
            outputs=self.outputs,
            step=self.step,
        )

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of A, 1/s, sorted by real part (descending)."""
        eig = np.linalg.eigvals(self.A)
        return eig[np.argsort(-eig.real, kind='stable')]

    @property
    def is_stable(self) -> bool:
        """True when every pole has a negative real part."""
        return bool(np.all(self.poles.real < 0))

    def controllability_rank(self) -> int:
        """Rank of the controllability matrix, judged on a scaled model."""
        return controllability_rank(self.A, self.B)

    def observability_rank(self) -> int:
        """Rank of the observability matrix, judged on a scaled model."""
        return observability_rank(self.A, self.C)

    def to_statespace(self):
        """Return a python-control continuous ``StateSpace`` with named signals."""
        import control

        return control.ss(
            self.A,
            self.B,
            self.C,
            self.D,
            states=list(self.states),
            inputs=list(self.inputs),
            outputs=list(self.outputs),
        )


def linearize(model, x_eq=None, u_eq=None, step: float = FD_STEP) -> LinearModel:
    """Linearise f(x, u) and h(x, u) by central finite differences.

    Parameters
    ----------
    model : MaggyModel
        The model.
    x_eq : array_like, shape (12,), optional
        Linearisation state (default: the centred magnet at the first equilibrium).
    u_eq : array_like, shape (n_s,), optional
        Linearisation input, A (default zero).
    step : float
        Finite-difference step (default 1e-6, in each variable's unit).

    Returns
    -------
    LinearModel
        A (12, 12), B (12, n_s), C (3k, 12), D (3k, n_s).
    """
    if x_eq is None:
        from .equilibria import find_equilibria

        found = find_equilibria(model)
        if not found:
            raise ValueError(f'{model!r} has no equilibrium to linearise about')
        x_eq = model.hover_state(found[0].z)
    x0 = np.asarray(x_eq, dtype=float).copy()
    u0 = np.zeros(model.n_inputs) if u_eq is None else np.asarray(u_eq, dtype=float).copy()
    if not step > 0:
        raise ValueError(f'step must be positive, got {step!r}')

    def jacobians(function, size_out):
        jx = np.empty((size_out, x0.size))
        ju = np.empty((size_out, u0.size))
        for i in range(x0.size):
            dx = np.zeros_like(x0)
            dx[i] = step
            jx[:, i] = (function(x0 + dx, u0) - function(x0 - dx, u0)) / (2 * step)
        for j in range(u0.size):
            du = np.zeros_like(u0)
            du[j] = step
            ju[:, j] = (function(x0, u0 + du) - function(x0, u0 - du)) / (2 * step)
        return jx, ju

    a, b = jacobians(model.dynamics, x0.size)
    c, d = jacobians(model.measurement, model.n_outputs)
    return LinearModel(
        A=a,
        B=b,
        C=c,
        D=d,
        x_eq=x0,
        u_eq=u0,
        y_eq=model.measurement(x0, u0),
        states=STATE_NAMES,
        inputs=input_names(model.n_inputs),
        outputs=output_names(len(model.params.sensors)),
        step=step,
    )


def _scaled_krylov_rank(a: np.ndarray, b: np.ndarray, tol: float) -> int:
    """Rank of [B, AB, ..., A^(n-1) B] after balancing, column and time scaling.

    The raw matrices span 1e-1 to 1e6, so the rank is judged on an equivalent
    model: A is balanced (diagonal similarity, exact in floating point), each
    input column of B is normalised, and time is scaled by A's spectral radius
    so that every Krylov block is of order one. Rank is then the number of
    singular values above ``tol`` times the largest.
    """
    n = a.shape[0]
    if b.size == 0:
        return 0
    _, (scale, perm) = matrix_balance(a, permute=False, separate=True)
    a_bal = a * scale[None, :] / scale[:, None]
    b_bal = b / scale[:, None]
    b_bal = b_bal / np.maximum(np.linalg.norm(b_bal, axis=0), np.finfo(float).tiny)
    radius = max(np.max(np.abs(np.linalg.eigvals(a_bal))), np.linalg.norm(a_bal, 2) * 1e-12)
    a_bal = a_bal / radius if radius > 0 else a_bal
    blocks = [b_bal]
    for _ in range(n - 1):
        nxt = a_bal @ blocks[-1]
        blocks.append(nxt / max(np.linalg.norm(nxt, 2), 1.0))
    sv = np.linalg.svd(np.hstack(blocks), compute_uv=False)
    return int(np.sum(sv > tol * sv[0]))


def controllability_rank(A, B, tol: float = 1e-9) -> int:
    """Rank of the controllability matrix, judged on a balanced, scaled model.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    tol : float
        Relative singular-value threshold.

    Returns
    -------
    int
    """
    return _scaled_krylov_rank(np.asarray(A, float), np.asarray(B, float), tol)


def observability_rank(A, C, tol: float = 1e-9) -> int:
    """Rank of the observability matrix (dual of :func:`controllability_rank`).

    Parameters
    ----------
    A : array_like, shape (n, n)
    C : array_like, shape (p, n)
    tol : float
        Relative singular-value threshold.

    Returns
    -------
    int
    """
    return _scaled_krylov_rank(np.asarray(A, float).T, np.asarray(C, float).T, tol)
