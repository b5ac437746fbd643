"""State estimation of the levitating magnet (ROS-free).

A linear KF about the equilibrium (compiled, the default), an EKF and a UKF
on the nonlinear model (compiled, filterpy's equations), with the same
sample handling:
one sample of sensor delay, the coils' direct field, chi-square gating per
sensor, frozen-sensor detection and predict-only steps. ``make_estimator``
chooses by :attr:`EstimatorConfig.filter`.
"""

from .base import Estimator, EstimatorStatus, nis_band
from .config import FILTERS, PREDICTIONS, EstimatorConfig, EstimatorConfigError
from .extended import ExtendedEstimator
from .freeze import FreezeDetector
from .linear import KalmanEstimator
from .unscented import UnscentedEstimator

__all__ = [
    'FILTERS',
    'PREDICTIONS',
    'EstimatorConfig',
    'EstimatorConfigError',
    'Estimator',
    'EstimatorStatus',
    'nis_band',
    'FreezeDetector',
    'KalmanEstimator',
    'ExtendedEstimator',
    'UnscentedEstimator',
    'make_estimator',
]

_KINDS = {'kf': KalmanEstimator, 'ekf': ExtendedEstimator, 'ukf': UnscentedEstimator}


def make_estimator(model, config: EstimatorConfig | None = None, linear=None) -> Estimator:
    """Build the estimator ``config.filter`` names.

    Parameters
    ----------
    model : MaggyModel
        The model the estimator believes.
    config : EstimatorConfig, optional
    linear : LinearModel, optional
        Linearisation about the equilibrium, to share one computation.
    """
    config = config or EstimatorConfig()
    return _KINDS[config.filter](model, config, linear)
