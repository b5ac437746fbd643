"""Filter consistency in the closed loop: average NEES and NIS against their chi-square bounds.

A filter is consistent when the covariance it reports matches its actual
error: the normalised estimation error squared ``NEES = e' P^-1 e`` (e the
estimate minus the true state, over the 10 reduced states) averages ``n =
10``, and the normalised innovation squared ``NIS = nu' S^-1 nu`` averages
its degrees of freedom (3 per accepted sensor). Over K samples the
time-averaged NIS of a consistent filter lies in ``chi2.ppf((0.025, 0.975),
sum of dof) / K`` with 95 % probability (Bar-Shalom, Li, Kirubarajan, 2001,
section 5.4.2: its innovations are white). The same bound for the NEES
assumes independent samples; its errors are correlated over the loop's time
constants, so that bound is narrower than the truth: a NEES near it still
passes, one far outside it is not consistent.

Above the upper bound a filter is *overconfident* (its gate rejects good
readings); below the lower one it is *conservative* (it trusts the model
less than it could).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

__all__ = ['ConsistencyResult', 'average_band', 'run_consistency']


def average_band(dof: int, samples: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided chi-square band of an average over ``samples`` of ``dof`` degrees in all.

    Parameters
    ----------
    dof : int
        Degrees of freedom of the sum (e.g. 10 per sample for the NEES).
    samples : int
        Samples averaged.
    probability : float
        Probability inside the band.

    Returns
    -------
    low, high : float
        ``chi2.ppf((1 -+ probability) / 2, dof) / samples``.
    """
    if samples < 1 or dof < 1:
        raise ValueError(f'need samples >= 1 and dof >= 1, got {samples!r} and {dof!r}')
    tail = (1.0 - probability) / 2.0
    return (
        float(chi2.ppf(tail, dof)) / samples,
        float(chi2.ppf(1.0 - tail, dof)) / samples,
    )


@dataclass(frozen=True)
class ConsistencyResult:
    """Average NEES and NIS of one closed-loop run.

    Attributes
    ----------
    filter : str
        ``kf``, ``ekf`` or ``ukf``.
    samples : int
        Samples averaged (after the settling time).
    nees : float
        Average NEES over the 10 reduced states.
    nees_band : tuple of float
        Its 95 % band.
    nees_states : ndarray, shape (10,)
        Average ``e_i^2 / P_ii`` per reduced state (1 when consistent).
    nis : float
        Average NIS per sample.
    nis_dof : float
        Average degrees of freedom per sample.
    nis_band : tuple of float
        Its 95 % band.
    crashed : bool
        The magnet fell (then the averages cover the samples before).
    """

    filter: str
    samples: int
    nees: float
    nees_band: tuple
    nees_states: np.ndarray
    nis: float
    nis_dof: float
    nis_band: tuple
    crashed: bool

    @property
    def nees_ok(self) -> bool:
        """True when the average NEES lies in its band."""
        return self.nees_band[0] <= self.nees <= self.nees_band[1]

    @property
    def nis_ok(self) -> bool:
        """True when the average NIS lies in its band."""
        return self.nis_band[0] <= self.nis <= self.nis_band[1]

    @staticmethod
    def verdict(value: float, band: tuple) -> str:
        """Return ``'ok'``, ``'overconfident'`` (above the band) or ``'conservative'``.

        Parameters
        ----------
        value : float
            Average NEES or NIS.
        band : tuple of float
            Its 95 % band ``(low, high)``.
        """
        if value > band[1]:
            return 'overconfident'
        return 'conservative' if value < band[0] else 'ok'


def run_consistency(
    params='maggy_v2',
    config=None,
    duration: float = 10.0,
    settle: float = 0.5,
    seed: int = 0,
    linear=None,
) -> ConsistencyResult:
    """Levitate in the simulator with the lab's noise and average the filter's NEES and NIS.

    The closed loop of :func:`~maglev_ros.control.closed_loop.make_closed_loop`
    (0.1 mT noise, 0.098 mT quantisation, one sample of sensor delay, coil
    dynamics, the LQR), from the equilibrium; the estimator records its
    covariance each sample.

    Parameters
    ----------
    params : str or MaggyModel
        Parameter set (plant and model alike).
    config : EstimatorConfig, optional
        The filter (default: the KF).
    duration : float
        Simulated time, s.
    settle : float
        Seconds left out at the start (the initial covariance's transient).
    seed : int
        Noise seed.
    linear : LinearModel, optional
        Linearisation of the model, to share.
    """
    from ..control.closed_loop import make_closed_loop
    from ..physics import MaggyModel, linearize, make_model
    from .config import EstimatorConfig

    model = params if isinstance(params, MaggyModel) else make_model(params)
    config = config or EstimatorConfig()
    lin = linear if linear is not None else linearize(model)
    loop = make_closed_loop(model, estimator=config, linear=lin, seed=seed)
    est = loop.estimator
    nr = est.n_reduced
    covariances = []
    step = est.step

    def recording_step(y, currents):
        x = step(y, currents)
        covariances.append(est._out_p[:nr, :nr].copy())
        return x

    est.step = recording_step  # this instance only: the loop calls est.step
    result = loop.run(duration)
    P = np.array(covariances)
    sel = np.flatnonzero(result.t >= settle)
    err = (result.estimate - result.x)[sel][:, est.reduced]
    P = P[sel]
    nees = np.einsum('ki,ki->k', err, np.linalg.solve(P, err[..., None])[..., 0])
    k = len(sel)
    dof = int(result.dof[sel].sum())
    return ConsistencyResult(
        filter=config.filter,
        samples=k,
        nees=float(nees.mean()),
        nees_band=average_band(nr * k, k),
        nees_states=np.mean(err**2 / np.einsum('kii->ki', P), axis=0),
        nis=float(result.nis[sel].sum() / k),
        nis_dof=dof / k,
        nis_band=average_band(dof, k),
        crashed=bool(result.crashed),
    )
