"""Grey-box identification: calibrate a board's physical model from its data (ROS-free).

The physics model's parameters form a named vector (:mod:`.parameters`) with
units, nominal values, bounds and free/fixed flags; prediction-error
minimisation estimates the free ones. The static part (:mod:`.static`) fits
the field against the coil currents recorded with the magnet absent or held
fixed; :mod:`.identifiability` reports what the data cannot identify;
:mod:`.export` writes the calibrated set as a parameter file that loads like
``config/maggy_v2.yaml``. The dynamic part (:mod:`.dynamic`) fits the
linearised model's Kalman predictor to levitation data (the magnet's mass and
polarisation, which static data cannot give); :mod:`.nonlinear` fits the
full nonlinear model's predictor with the same Kalman gain (``nlgreyest``-like,
``calibrate_dynamic(..., form='nonlinear')``); :mod:`.closed_loop_fit` fits
the full nonlinear model by simulating the closed loop with the known
estimator and controller (a slower cross-check).
"""

from .closed_loop_fit import ClosedLoopFit, LoopSetup, calibrate_closed_loop
from .dynamic import DynamicCalibration, calibrate_dynamic
from .errors import GreyBoxError
from .export import parameters_to_mapping, write_parameters
from .identifiability import Identifiability, Unidentified, analyse, correlated_pairs
from .nonlinear import NonlinearGreyBoxProblem
from .parameters import POSE_NAMES, ParameterSpec, ParameterVector, parameter_vector
from .predictor import GreyBoxSystem, LevitationExperiment, LinearGreyBoxProblem, noise_level
from .static import (
    MAGNET_STATES,
    AffineStatistics,
    StaticCalibration,
    StaticExperiment,
    StaticProblem,
    ValidationFit,
    best_delay,
    calibrate_static,
    fit_percent,
)
from .verdict import Verdict, assess

__all__ = [
    'GreyBoxError',
    'ParameterSpec',
    'ParameterVector',
    'parameter_vector',
    'POSE_NAMES',
    'parameters_to_mapping',
    'write_parameters',
    'Identifiability',
    'Unidentified',
    'analyse',
    'correlated_pairs',
    'MAGNET_STATES',
    'StaticExperiment',
    'AffineStatistics',
    'StaticProblem',
    'ValidationFit',
    'StaticCalibration',
    'best_delay',
    'calibrate_static',
    'fit_percent',
    'LevitationExperiment',
    'GreyBoxSystem',
    'LinearGreyBoxProblem',
    'DynamicCalibration',
    'calibrate_dynamic',
    'noise_level',
    'NonlinearGreyBoxProblem',
    'LoopSetup',
    'ClosedLoopFit',
    'calibrate_closed_loop',
    'Verdict',
    'assess',
]
