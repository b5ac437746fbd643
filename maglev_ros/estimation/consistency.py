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

__all__ = [
    'MATCHED_NOISE',
    'ConsistencyResult',
    'average_band',
    'correlation_time',
    'matched_config',
    'prediction_errors',
    'run_consistency',
    'steady_covariance',
]

#: Process noise that stands for each filter's own prediction error in the
#: simulated lab, per parameter set and filter: ``(current_noise A,
#: acceleration_noise m/s^2 (horizontal), vertical_acceleration_noise m/s^2,
#: angular_acceleration_noise rad/s^2)``. The plant has no random force: the
#: model's error is the coil currents' ramp inside a sample, seen through B
#: (:func:`prediction_errors`: the errors of x, beta, vx and wy move together,
#: as do y, alpha, vy and wx), and a slow vertical drift (the KF's
#: linearisation). So the tuning is a current noise and a vertical one, no
#: independent horizontal or angular accelerations: those put variance where
#: the errors have none (the x-vx and y-vy directions P is thinnest in) and
#: left the NEES at half its degrees of freedom (4.3-5.5 with the earlier
#: diagonal tuning). Values found by NEES (10 s runs, docs/estimation.md).
MATCHED_NOISE = {
    ('maggy_v2', 'kf'): (4.4e-4, 0.0, 0.007, 0.0),
    ('maggy_v2', 'ekf'): (2.4e-4, 0.0, 0.007, 0.0),
    ('maggy_v2', 'ukf'): (2.4e-4, 0.0, 0.007, 0.0),
    ('maggy_v4', 'kf'): (5.3e-4, 0.0, 0.02, 0.0),
    ('maggy_v4', 'ekf'): (3.6e-4, 0.0, 0.012, 0.0),
    ('maggy_v4', 'ukf'): (3.7e-4, 0.0, 0.012, 0.0),
}


def matched_config(params: str, kind: str, **changes):
    """Return the filter ``kind`` with the process noise of :data:`MATCHED_NOISE` (``params``).

    Parameters
    ----------
    params : str
        ``maggy_v2`` or ``maggy_v4``.
    kind : str
        ``kf``, ``ekf`` or ``ukf``.
    **changes
        Other :class:`~maglev_ros.estimation.EstimatorConfig` fields.

    Returns
    -------
    EstimatorConfig
    """
    from .config import EstimatorConfig

    if (params, kind) not in MATCHED_NOISE:
        raise ValueError(
            f'no matched process noise for {params!r} and {kind!r}: one of {sorted(MATCHED_NOISE)}'
        )
    current, acceleration, vertical, angular = MATCHED_NOISE[(params, kind)]
    return EstimatorConfig(
        filter=kind,
        current_noise=current,
        acceleration_noise=acceleration,
        vertical_acceleration_noise=vertical,
        angular_acceleration_noise=angular,
        **changes,
    )


def average_band(dof: float, samples: float, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided chi-square band of an average over ``samples`` of ``dof`` degrees in all.

    Parameters
    ----------
    dof : float
        Degrees of freedom of the sum (e.g. 10 per sample for the NEES).
    samples : float
        Samples averaged (independent ones: an effective count may be fractional).
    probability : float
        Probability inside the band.

    Returns
    -------
    low, high : float
        ``chi2.ppf((1 -+ probability) / 2, dof) / samples``.
    """
    if not (samples >= 1 and dof >= 1):
        raise ValueError(f'need samples >= 1 and dof >= 1, got {samples!r} and {dof!r}')
    tail = (1.0 - probability) / 2.0
    return (
        float(chi2.ppf(tail, dof)) / samples,
        float(chi2.ppf(1.0 - tail, dof)) / samples,
    )


def correlation_time(series: np.ndarray, window: float = 5.0) -> float:
    """Integrated autocorrelation time of a series, in samples (1: white).

    ``tau = 1 + 2 sum_j rho_j`` with the sum over lags ``j < M``, ``M`` the
    smallest lag with ``M >= window * tau(M)`` (Sokal's automatic window:
    the noise of the far lags left out). The mean of ``K`` samples of a
    stationary series has the variance of the mean of ``K / tau`` independent
    ones: ``K / tau`` is the effective sample count.

    Parameters
    ----------
    series : array_like, shape (K,)
        The samples in time order.
    window : float
        Sokal's constant (5: the usual choice).

    Returns
    -------
    float
        ``tau`` >= 1, samples.
    """
    x = np.asarray(series, dtype=float)
    x = x - x.mean()
    n = x.shape[0]
    if n < 2 or not np.any(x):
        return 1.0
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:n]
    acf /= acf[0]
    taus = 2.0 * np.cumsum(acf) - 1.0
    lags = np.arange(n)
    ok = lags >= window * taus
    m = int(np.argmax(ok)) if ok.any() else n - 1
    return max(1.0, float(taus[m]))


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
        Its 95 % band over the effective sample count.
    nees_correlation : float
        Integrated autocorrelation time of the NEES series, samples
        (:func:`correlation_time`): the band is that of ``samples /
        nees_correlation`` independent samples.
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
    nees_correlation: float
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


def prediction_errors(
    params='maggy_v2',
    kind: str = 'kf',
    duration: float = 3.0,
    seed: int = 1,
    linear=None,
) -> np.ndarray:
    """Return the filter's own one-step prediction error on the true plant, (K, 10).

    Levitates for ``duration`` s in the simulated lab (as :func:`run_consistency`,
    its default filter of ``kind`` in the loop; the first 0.5 s left out), then
    predicts each sample's *true* state one sample on with the filter's own
    prediction (its model and integrator, the currents' trapezoidal hold) and
    subtracts the true state there: ``w(k) = x(k+1) - f(x(k), u)``, reduced
    states. The simulated plant has no random force: ``w`` is the model's
    error (the coil current's ramp inside a sample, the KF's linearisation).

    Parameters
    ----------
    params : str or MaggyModel
        Parameter set (plant and model alike).
    kind : str
        ``kf``, ``ekf`` or ``ukf``.
    duration : float
        Simulated time, s.
    seed : int
        Noise seed (another than the consistency run's: independent data).
    linear : LinearModel, optional
    """
    from ..control.closed_loop import make_closed_loop
    from ..physics import MaggyModel, linearize, make_model
    from . import make_estimator
    from .config import EstimatorConfig

    model = params if isinstance(params, MaggyModel) else make_model(params)
    lin = linear if linear is not None else linearize(model)
    config = EstimatorConfig(filter=kind)
    result = make_closed_loop(model, estimator=config, linear=lin, seed=seed).run(duration)
    if result.crashed:
        raise RuntimeError(f'the {kind.upper()} loop crashed: {result.reason}')
    est = make_estimator(model, config, lin)
    nr, n = est.n_reduced, est.n_states
    dx = (result.x - est.x_eq)[:, est.reduced]
    across = 0.5 * (result.currents[:-1] + result.currents[1:])
    tiny = 1e-26 * np.eye(n)  # a point (1e-13 m): the UKF needs a factor
    start = int(np.searchsorted(result.t, 0.5))
    w = np.empty((len(dx) - 1 - start, nr))
    state = np.zeros(n)
    for j, k in enumerate(range(start, len(dx) - 1)):
        state[:nr] = dx[k]
        est._set_state(state, tiny)
        est._predict(across[k])
        w[j] = dx[k + 1] - est.deviation[:nr]
    return w


def steady_covariance(model, config, linear=None) -> np.ndarray:
    """Steady-state prior covariance of the linear filter with ``config``'s noise, (n, n).

    The solution of the discrete algebraic Riccati equation with the KF's F,
    H, Q and R (``scipy.linalg.solve_discrete_are``): the covariance the
    filter's prior settles to with every reading accepted.

    Parameters
    ----------
    model : MaggyModel
    config : EstimatorConfig
        Its noise settings (its ``filter`` is ignored).
    linear : LinearModel, optional
    """
    import dataclasses

    from scipy.linalg import solve_discrete_are

    from .linear import KalmanEstimator

    kf = KalmanEstimator(
        model, dataclasses.replace(config, filter='kf', magnet_strength=False), linear
    )
    p = solve_discrete_are(kf.F.T, kf.H.T, kf.Q, np.diag(kf.r_diag))
    return 0.5 * (p + p.T)


def run_consistency(
    params='maggy_v2',
    config=None,
    duration: float = 10.0,
    settle: float = 0.5,
    seed: int = 0,
    linear=None,
    start: str = 'steady',
) -> ConsistencyResult:
    """Levitate in the simulator with the lab's noise and average the filter's NEES and NIS.

    The closed loop of :func:`~maglev_ros.control.closed_loop.make_closed_loop`
    (0.1 mT noise, 0.098 mT quantisation, one sample of sensor delay, coil
    dynamics, the LQR), from the equilibrium; the estimator records its
    covariance each sample.

    The magnet and the estimate start at the equilibrium: the initial error
    is zero. From its configured prior (``start='prior'``: 1 mm, 0.03 rad,
    ...) a filter with a small process noise forgets that prior only slowly
    (its z and tilt variances fall about as 1 / t: 4x and 9x their steady
    values after 0.5 s, 1.1x and 1.7x after 3 s), so the NEES of the first
    seconds measures the prior, not the filter. ``start='steady'`` (default)
    starts from the steady-state covariance instead (the linear filter's, the
    discrete Riccati equation's solution with the same F, H, Q, R), which the
    error then reaches within its correlation time.

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
    start : str
        ``'steady'`` or ``'prior'``: the covariance the filter starts from.
    """
    if start not in ('steady', 'prior'):
        raise ValueError(f"start must be 'steady' or 'prior', got {start!r}")
    from ..control.closed_loop import make_closed_loop
    from ..physics import MaggyModel, linearize, make_model
    from .config import EstimatorConfig

    model = params if isinstance(params, MaggyModel) else make_model(params)
    config = config or EstimatorConfig()
    lin = linear if linear is not None else linearize(model)
    loop = make_closed_loop(model, estimator=config, linear=lin, seed=seed)
    est = loop.estimator
    if start == 'steady':
        steady = steady_covariance(model, config, lin)
        est.initial_covariance = lambda: steady.copy()  # this instance: the loop resets it
        est.reset()
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
    tau = correlation_time(nees)
    return ConsistencyResult(
        filter=config.filter,
        samples=k,
        nees=float(nees.mean()),
        nees_band=average_band(nr * k / tau, k / tau),
        nees_correlation=tau,
        nees_states=np.mean(err**2 / np.einsum('kii->ki', P), axis=0),
        nis=float(result.nis[sel].sum() / k),
        nis_dof=dof / k,
        nis_band=average_band(dof, k),
        crashed=bool(result.crashed),
    )
