"""SINDy with control inputs (pysindy) on state trajectories, and its linearisation.

Sparse identification of nonlinear dynamics (Brunton, Proctor, Kutz 2016;
with control, SINDYc) fits ``dx/dt = Xi' theta(x, u)`` with ``theta`` a
library of candidate functions (here polynomials of the states and inputs) and
a sparse ``Xi`` found by sequentially thresholded least squares.  The fitting
is pysindy's (:class:`pysindy.SINDy`, :class:`pysindy.STLSQ`,
:class:`pysindy.PolynomialLibrary`); this module prepares the trajectories
(states and inputs of one or several experiments, optionally shifted to an
operating point and scaled to readable units), prints the equations, and
linearises the identified model at a point for a check against the physics
(:func:`maglev_ros.physics.linearize`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    'COIL_INPUTS',
    'REDUCED_INDEX',
    'REDUCED_STATES',
    'EigenvalueCheck',
    'SindyModel',
    'eigenvalue_check',
    'sindy',
    'sindy_magnet',
]


@dataclass(frozen=True, eq=False)
class SindyModel:
    """A SINDy model ``dx/dt = f(x, u)`` in scaled, shifted variables.

    The model's variables are ``xs = (x - x_ref) * state_scale`` and
    ``us = (u - u_ref) * input_scale``; :meth:`rates` and :meth:`linearize`
    take and return physical units.

    Attributes
    ----------
    model : pysindy.SINDy
        The fitted pysindy model.
    state_names, input_names : tuple of str
        Variable names in the equations.
    x_ref, u_ref : ndarray
        Operating point subtracted before scaling.
    state_scale, input_scale : ndarray
        Scales applied after the shift.
    """

    model: object
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    x_ref: np.ndarray
    u_ref: np.ndarray
    state_scale: np.ndarray
    input_scale: np.ndarray

    @property
    def coefficients(self) -> np.ndarray:
        """``Xi'``, shape (n_states, n_features), in the scaled variables."""
        return np.asarray(self.model.coefficients())

    @property
    def feature_names(self) -> list[str]:
        """Library functions, in the order of the coefficient columns."""
        return list(self.model.get_feature_names())

    def equations(self, precision: int = 4) -> list[str]:
        """Readable equations ``d(name)/dt = ...``, one per state (zero terms left out).

        Parameters
        ----------
        precision : int
            Decimals of the coefficients (pysindy's ``equations(precision)``).
        """
        rhs = [
            ' '.join(text.split()).replace('+ -', '- ') for text in self.model.equations(precision)
        ]
        return [f'd({name})/dt = {text}' for name, text in zip(self.state_names, rhs, strict=True)]

    def terms(self, state: str) -> dict[str, float]:
        """Non-zero terms of one state's equation: library function -> coefficient.

        Parameters
        ----------
        state : str
            Name of the state, one of ``state_names``.
        """
        row = self.coefficients[self.state_names.index(state)]
        return {name: float(c) for name, c in zip(self.feature_names, row, strict=True) if c}

    def __str__(self) -> str:
        head = (
            f'SINDy model: {len(self.state_names)} states, {len(self.input_names)} inputs, '
            f'{int(np.count_nonzero(self.coefficients))} of {self.coefficients.size} '
            'library terms active'
        )
        return '\n'.join([head] + ['  ' + line for line in self.equations()])

    def rates(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``dx/dt`` in physical units for states ``x`` (N, n) and inputs ``u`` (N, m).

        Parameters
        ----------
        x : ndarray, shape (N, n) or (n,)
            States in physical units (not shifted, not scaled).
        u : ndarray, shape (N, m) or (m,)
            Inputs in physical units, at the same samples.

        Returns
        -------
        ndarray, shape (N, n)
            State derivatives, physical units per second.
        """
        x = np.atleast_2d(np.asarray(x, dtype=float))
        u = np.atleast_2d(np.asarray(u, dtype=float))
        xs = (x - self.x_ref) * self.state_scale
        us = (u - self.u_ref) * self.input_scale
        return np.asarray(self.model.predict(xs, u=us)) / self.state_scale

    def linearize(
        self, x0: np.ndarray | None = None, u0: np.ndarray | None = None, step: float = 1e-6
    ) -> tuple[np.ndarray, np.ndarray]:
        """Jacobians ``A = df/dx`` (n, n) and ``B = df/du`` (n, m) at ``(x0, u0)``, physical units.

        Central differences with steps of ``step`` in the scaled variables
        (exact for the polynomial library up to rounding).

        Parameters
        ----------
        x0 : ndarray, shape (n,), optional
            State of the linearisation, physical units (default ``x_ref``).
        u0 : ndarray, shape (m,), optional
            Input of the linearisation, physical units (default ``u_ref``).
        step : float
            Finite-difference step in the scaled variables.
        """
        x0 = self.x_ref if x0 is None else np.asarray(x0, dtype=float)
        u0 = self.u_ref if u0 is None else np.asarray(u0, dtype=float)
        n, m = len(x0), len(u0)
        A = np.zeros((n, n))
        B = np.zeros((n, m))
        for k in range(n):
            h = step / self.state_scale[k]
            dx = np.zeros(n)
            dx[k] = h
            A[:, k] = (self.rates(x0 + dx, u0) - self.rates(x0 - dx, u0))[0] / (2 * h)
        for k in range(m):
            h = step / self.input_scale[k]
            du = np.zeros(m)
            du[k] = h
            B[:, k] = (self.rates(x0, u0 + du) - self.rates(x0, u0 - du))[0] / (2 * h)
        return A, B


def _as_list(value: np.ndarray | Sequence[np.ndarray]) -> list[np.ndarray]:
    if isinstance(value, np.ndarray):
        return [value]
    return [np.asarray(v, dtype=float) for v in value]


def sindy(
    x: np.ndarray | Sequence[np.ndarray],
    u: np.ndarray | Sequence[np.ndarray],
    dt: float,
    degree: int = 2,
    threshold: float = 0.05,
    x_dot: np.ndarray | Sequence[np.ndarray] | None = None,
    state_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
    x_ref: np.ndarray | None = None,
    u_ref: np.ndarray | None = None,
    state_scale: np.ndarray | None = None,
    input_scale: np.ndarray | None = None,
    alpha: float = 0.0,
) -> SindyModel:
    """Fit a SINDy model with control inputs by pysindy's STLSQ.

    Parameters
    ----------
    x : ndarray, shape (N, n), or a sequence of them
        State trajectories (several: one per experiment, not joined).
    u : ndarray, shape (N, m), or a sequence of them
        Inputs at the same samples.
    dt : float
        Sample time in seconds.
    degree : int
        Polynomial degree of the library (states and inputs together).
    threshold : float
        STLSQ threshold on the coefficients (in the scaled variables).
    x_dot : ndarray or sequence, optional
        Known derivatives (physical units); default: pysindy's second-order
        finite differences.
    state_names, input_names : sequence of str, optional
        Names in the equations (default ``x0..``, ``u0..``).
    x_ref, u_ref : ndarray, optional
        Operating point subtracted first (default zero).
    state_scale, input_scale : ndarray, optional
        Unit scales applied after the shift (default one), e.g. 1e3 for m -> mm.
    alpha : float
        Ridge regularisation of STLSQ.

    Returns
    -------
    SindyModel
        The fitted model.
    """
    import pysindy as ps

    xs, us = _as_list(x), _as_list(u)
    if len(xs) != len(us):
        raise ValueError(f'{len(xs)} state trajectories but {len(us)} input trajectories')
    us = [v.reshape(v.shape[0], -1) for v in us]
    n, m = xs[0].shape[1], us[0].shape[1]
    for k, (a, b) in enumerate(zip(xs, us, strict=True)):
        if a.ndim != 2 or a.shape[1] != n or b.shape[1] != m or a.shape[0] != b.shape[0]:
            raise ValueError(
                f'experiment {k + 1}: states {a.shape} and inputs {b.shape} do not match '
                f'(expected (N, {n}) and (N, {m}))'
            )
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise ValueError(f'experiment {k + 1}: states or inputs contain NaN or inf')
    x_ref = np.zeros(n) if x_ref is None else np.asarray(x_ref, dtype=float)
    u_ref = np.zeros(m) if u_ref is None else np.asarray(u_ref, dtype=float)
    sx = np.ones(n) if state_scale is None else np.asarray(state_scale, dtype=float)
    su = np.ones(m) if input_scale is None else np.asarray(input_scale, dtype=float)
    state_names = tuple(state_names or (f'x{k}' for k in range(n)))
    input_names = tuple(input_names or (f'u{k}' for k in range(m)))
    scaled_x = [(a - x_ref) * sx for a in xs]
    scaled_u = [(b - u_ref) * su for b in us]
    scaled_dot = None if x_dot is None else [d * sx for d in _as_list(x_dot)]
    model = ps.SINDy(
        optimizer=ps.STLSQ(threshold=threshold, alpha=alpha),
        feature_library=ps.PolynomialLibrary(degree=degree),
    )
    names = list(state_names) + list(input_names)
    if len(scaled_x) == 1:
        model.fit(
            scaled_x[0],
            t=dt,
            u=scaled_u[0],
            x_dot=None if scaled_dot is None else scaled_dot[0],
            feature_names=names,
        )
    else:  # pysindy 2 takes several trajectories as lists
        model.fit(scaled_x, t=dt, u=scaled_u, x_dot=scaled_dot, feature_names=names)
    return SindyModel(model, state_names, input_names, x_ref, u_ref, sx, su)


#: The magnet's 10 states without yaw and yaw rate (the physics' ``reduced()`` order),
#: indices into the 12-state.
REDUCED_STATES = ('x', 'y', 'z', 'alpha', 'beta', 'vx', 'vy', 'vz', 'wx', 'wy')
REDUCED_INDEX = (0, 1, 2, 3, 4, 6, 7, 8, 9, 10)
COIL_INPUTS = ('i1', 'i2', 'i3', 'i4')


def sindy_magnet(
    x: np.ndarray | Sequence[np.ndarray],
    u: np.ndarray | Sequence[np.ndarray],
    dt: float,
    linear: object,
    degree: int = 2,
    threshold: float = 0.5,
) -> SindyModel:
    """SINDy of the magnet: 10 states around the equilibrium in mm, mrad, mm/s, mrad/s.

    Parameters
    ----------
    x : ndarray, shape (N, 12), or a sequence of them
        12-states (position m, ZYX angles rad, world velocity m/s, body rates rad/s).
    u : ndarray, shape (N, 4), or a sequence of them
        Coil currents, A.
    dt : float
        Sample time, s.
    linear : LinearModel
        The physics linearisation (:func:`maglev_ros.physics.linearize`): its
        equilibrium ``x_eq``, ``u_eq`` is the operating point.
    degree : int
        Polynomial degree of the library.
    threshold : float
        STLSQ threshold in the scaled units.
    """
    keep = list(REDUCED_INDEX)
    return sindy(
        [a[:, keep] for a in _as_list(x)],
        u,
        dt,
        degree=degree,
        threshold=threshold,
        state_names=REDUCED_STATES,
        input_names=COIL_INPUTS,
        x_ref=np.asarray(linear.x_eq)[keep],
        u_ref=np.asarray(linear.u_eq),
        state_scale=np.full(len(keep), 1e3),
    )


@dataclass(frozen=True)
class EigenvalueCheck:
    """One eigenvalue of the physics linearisation and SINDy's nearest.

    Attributes
    ----------
    name : str
        ``unstable``, ``oscillatory (slow)`` or ``oscillatory (fast)``.
    physics, found : complex
        Eigenvalues, 1/s.
    error : float
        ``|found - physics| / |physics|``.
    """

    name: str
    physics: complex
    found: complex
    error: float


def eigenvalue_check(model: SindyModel, linear: object) -> list[EigenvalueCheck]:
    """Compare the SINDy model's linearisation with the physics' unstable and oscillatory modes.

    Parameters
    ----------
    model : SindyModel
        From :func:`sindy_magnet` (its reference point is the equilibrium).
    linear : LinearModel
        The physics linearisation; its ``reduced()`` 10-state model is compared.
    """
    A, _ = model.linearize()
    found = np.linalg.eigvals(A)
    truth = np.linalg.eigvals(linear.reduced().A)
    oscillatory = [p for p in truth if p.imag > 1e-6 * np.abs(truth).max()]
    targets = [('unstable', truth[np.argmax(truth.real)])]
    if oscillatory:
        targets += [
            ('oscillatory (slow)', min(oscillatory, key=abs)),
            ('oscillatory (fast)', max(oscillatory, key=abs)),
        ]
    out = []
    for name, target in targets:
        nearest = found[np.argmin(np.abs(found - target))]
        out.append(EigenvalueCheck(name, complex(target), complex(nearest),
                                   float(abs(nearest - target) / abs(target))))  # fmt: skip
    return out
