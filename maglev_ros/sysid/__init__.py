"""ROS-free system identification for the Maggy lab (MATLAB System Identification workflow).

Data sets (:class:`IdData`, :func:`load_data`), estimators (:func:`arx`, :func:`iv4`,
:func:`armax`, :func:`oe`, :func:`bj`, recursive :func:`rls_arx` /
:class:`RecursiveArx`), models (:class:`PolyModel`), validation
(:func:`compare`, :func:`resid`, :func:`fit_percent`), order selection
(:func:`arxstruc`, :func:`selstruc`, :func:`delayest`), model files
(:func:`save_model`, :func:`load_model`, :func:`export_mat`) and PNG plots.

Beyond the linear fits: polynomial NARX with FROLS (:func:`narx`), SINDy with
control (:func:`sindy`, through pysindy; :func:`bag_states` reads a bag's
states), confidence bands
(:func:`frequency_band`, :func:`step_band`, :func:`simulation_band`),
cross-validation over experiments (:func:`kfold`, :func:`by_experiment`) and
balanced truncation (:func:`balanced_truncation`).
"""

from .armax import armax
from .arx import arx, least_squares
from .confidence import Band, frequency_band, simulation_band, step_band
from .criteria import aic, fit_percent, fpe, mdl
from .datafile import DataFileError, load_data
from .dataset import IdData, merge
from .experiments import FoldTable, by_experiment, kfold
from .frols import frols
from .io import export_mat, load_model, model_from_dict, model_to_dict, save_model
from .iv import iv4
from .model import DivergenceError, EstimationReport, PolyModel
from .narx import NarxModel, narx
from .oe_bj import bj, oe
from .orders import OrderError, Orders, make_orders
from .plots import bode_figure, bode_plot, compare_figure, compare_plot, resid_figure, resid_plot
from .reduction import Reduction, StateSpaceModel, balanced_truncation
from .rls import RecursiveArx, RlsResult, rls_arx
from .selection import OrderSearch, arxstruc, delayest, selstruc
from .sindy import SindyModel, sindy
from .state_trajectories import StateTrajectory, bag_states
from .validation import CompareResult, ResidualAnalysis, compare, resid

__all__ = [
    'Band',
    'CompareResult',
    'DataFileError',
    'DivergenceError',
    'EstimationReport',
    'FoldTable',
    'IdData',
    'NarxModel',
    'OrderError',
    'OrderSearch',
    'Orders',
    'PolyModel',
    'RecursiveArx',
    'Reduction',
    'ResidualAnalysis',
    'RlsResult',
    'SindyModel',
    'StateTrajectory',
    'StateSpaceModel',
    'aic',
    'armax',
    'arx',
    'arxstruc',
    'bag_states',
    'balanced_truncation',
    'bj',
    'bode_figure',
    'bode_plot',
    'by_experiment',
    'compare',
    'compare_figure',
    'compare_plot',
    'delayest',
    'export_mat',
    'fit_percent',
    'fpe',
    'frequency_band',
    'frols',
    'iv4',
    'kfold',
    'least_squares',
    'load_data',
    'load_model',
    'make_orders',
    'mdl',
    'merge',
    'model_from_dict',
    'model_to_dict',
    'narx',
    'oe',
    'resid',
    'resid_figure',
    'resid_plot',
    'rls_arx',
    'save_model',
    'selstruc',
    'simulation_band',
    'sindy',
    'step_band',
]
