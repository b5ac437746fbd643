"""Confidence bands of identified linear models from their parameter covariance.

As the toolbox's ``showConfidence``, the uncertainty of a response is
propagated to first order (Gauss' approximation, Ljung sec. 9.6): for a
response ``r(theta)`` (a magnitude, a phase, a simulated output sample)

``std r = sqrt(diag(J P J'))``, ``J = dr / dtheta``,

with ``P`` the model's parameter covariance.  ``J`` is taken by central
differences with steps of ``1e-3`` standard deviations of each parameter, so
any structure (ARX, IV, ARMAX, OE, BJ, MIMO) is handled by the model's own
response code.  The band drawn is ``r +- sigma std r`` (default 3 standard
deviations, as the toolbox).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .dataset import IdData
from .model import PolyModel

__all__ = [
    'DEFAULT_SIGMA',
    'Band',
    'frequency_band',
    'response_std',
    'simulation_band',
    'step_band',
    'with_theta',
]

DEFAULT_SIGMA = 3.0
RELATIVE_STEP = 1e-3  # finite-difference step in standard deviations of each parameter


@dataclass(frozen=True)
class Band:
    """A response with its standard deviation.

    Attributes
    ----------
    value : ndarray
        The model's response.
    std : ndarray
        Its standard deviation, same shape.
    sigma : float
        Standard deviations of the band (``value +- sigma * std``).
    """

    value: np.ndarray
    std: np.ndarray
    sigma: float = DEFAULT_SIGMA

    @property
    def lower(self) -> np.ndarray:
        """``value - sigma * std``."""
        return self.value - self.sigma * self.std

    @property
    def upper(self) -> np.ndarray:
        """``value + sigma * std``."""
        return self.value + self.sigma * self.std

    def contains(self, truth: np.ndarray) -> np.ndarray:
        """Boolean array: is ``truth`` within the band.

        Parameters
        ----------
        truth : ndarray
            True response, the shape of ``value`` (or broadcastable to it).
        """
        return (truth >= self.lower) & (truth <= self.upper)


def with_theta(model: PolyModel, theta: np.ndarray) -> PolyModel:
    """Return the same model structure with other parameters (no report, no covariance).

    Parameters
    ----------
    model : PolyModel
        The model whose structure, orders, sample time, noise variance, names
        and units are kept.
    theta : ndarray, shape (n_theta,)
        The new parameter vector, ordered as ``model.theta``.
    """
    return PolyModel(
        model.structure,
        model.orders,
        theta,
        model.Ts,
        model.noise_variance,
        None,
        model.output_names,
        model.input_names,
        model.output_units,
        model.input_units,
    )


def response_std(
    model: PolyModel, response: Callable[[PolyModel], np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """First-order standard deviation of a real response of the model.

    Parameters
    ----------
    model : PolyModel
        A model with a parameter covariance.
    response : callable
        ``response(model) -> ndarray`` (any shape, real).

    Returns
    -------
    value, std : ndarray
        The response and its standard deviation, same shape.
    """
    if model.covariance is None:
        raise ValueError('the model has no parameter covariance: no confidence band')
    value = np.asarray(response(model), dtype=float)
    P = np.asarray(model.covariance, dtype=float)
    sd = np.sqrt(np.clip(np.diag(P), 0.0, None))
    J = np.zeros((value.size, len(model.theta)))
    for k in range(len(model.theta)):
        h = RELATIVE_STEP * (sd[k] if sd[k] > 0 else max(abs(model.theta[k]), 1.0) * 1e-8)
        plus = model.theta.copy()
        minus = model.theta.copy()
        plus[k] += h
        minus[k] -= h
        rp = np.asarray(response(with_theta(model, plus)), dtype=float).ravel()
        rm = np.asarray(response(with_theta(model, minus)), dtype=float).ravel()
        J[:, k] = (rp - rm) / (2 * h)
    var = np.einsum('ij,jk,ik->i', J, P, J)
    return value, np.sqrt(np.clip(var, 0.0, None)).reshape(value.shape)


def frequency_band(
    model: PolyModel, f: np.ndarray, sigma: float = DEFAULT_SIGMA
) -> tuple[Band, Band]:
    """Bands of the magnitude (dB) and phase (degrees) of ``u -> y``.

    Parameters
    ----------
    model : PolyModel
        A model with a parameter covariance.
    f : array_like, shape (nf,)
        Frequencies in Hz.
    sigma : float
        Standard deviations of the band.

    Returns
    -------
    magnitude, phase : Band
        Values of shape (nf, ny, nu): magnitude in dB, phase in degrees
        (unwrapped along frequency).
    """
    f = np.atleast_1d(np.asarray(f, dtype=float))

    def magnitude(m: PolyModel) -> np.ndarray:
        return 20 * np.log10(np.maximum(np.abs(m.freqresp(f)), 1e-300))

    base = model.freqresp(f)

    def phase(m: PolyModel) -> np.ndarray:  # relative to the nominal: no wrap jumps
        return np.degrees(np.angle(m.freqresp(f) / np.where(base == 0, 1, base)))

    mag, mag_std = response_std(model, magnitude)
    _, phase_std = response_std(model, phase)
    nominal = np.degrees(np.unwrap(np.angle(base), axis=0))
    return Band(mag, mag_std, sigma), Band(nominal, phase_std, sigma)


def simulation_band(
    model: PolyModel, data: IdData | np.ndarray, sigma: float = DEFAULT_SIGMA
) -> Band:
    """Band of the simulated output (zero initial state), shape (N, ny).

    Parameters
    ----------
    model : PolyModel
        A model with a parameter covariance.
    data : IdData or ndarray, shape (N, nu)
        Inputs.
    sigma : float
        Standard deviations of the band.
    """
    value, std = response_std(model, lambda m: m.simulate(data))
    return Band(value, std, sigma)


def step_band(model: PolyModel, n_samples: int, sigma: float = DEFAULT_SIGMA) -> Band:
    """Band of the unit-step responses, shape (n_samples, ny, nu) (one step per input).

    Parameters
    ----------
    model : PolyModel
        A model with a parameter covariance.
    n_samples : int
        Samples of the response.
    sigma : float
        Standard deviations of the band.
    """
    steps = [np.zeros((n_samples, model.nu)) for _ in range(model.nu)]
    for j, u in enumerate(steps):
        u[:, j] = 1.0

    def response(m: PolyModel) -> np.ndarray:
        return np.stack([m.simulate(u) for u in steps], axis=2)

    value, std = response_std(model, response)
    return Band(value, std, sigma)
