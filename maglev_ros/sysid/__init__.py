"""ROS-free system identification for the Maggy lab (MATLAB System Identification workflow).

Data sets (:class:`IdData`, :func:`load_data`), estimators (:func:`arx`, :func:`iv4`,
:func:`armax`, :func:`oe`, :func:`bj`, recursive :func:`rls_arx` /
:class:`RecursiveArx`), models (:class:`PolyModel`), validation
(:func:`compare`, :func:`resid`, :func:`fit_percent`), order selection
(:func:`arxstruc`, :func:`selstruc`, :func:`delayest`), model files
(:func:`save_model`, :func:`load_model`, :func:`export_mat`) and PNG plots.
"""

from .armax import armax
from .arx import arx, least_squares
from .criteria import aic, fit_percent, fpe, mdl
from .datafile import DataFileError, load_data
from .dataset import IdData, merge
from .io import export_mat, load_model, model_from_dict, model_to_dict, save_model
from .iv import iv4
from .model import DivergenceError, EstimationReport, PolyModel
from .oe_bj import bj, oe
from .orders import OrderError, Orders, make_orders
from .plots import bode_figure, bode_plot, compare_figure, compare_plot, resid_figure, resid_plot
from .rls import RecursiveArx, RlsResult, rls_arx
from .selection import OrderSearch, arxstruc, delayest, selstruc
from .validation import CompareResult, ResidualAnalysis, compare, resid

__all__ = [
    'CompareResult',
    'DataFileError',
    'DivergenceError',
    'EstimationReport',
    'IdData',
    'OrderError',
    'OrderSearch',
    'Orders',
    'PolyModel',
    'RecursiveArx',
    'ResidualAnalysis',
    'RlsResult',
    'aic',
    'armax',
    'arx',
    'arxstruc',
    'bj',
    'bode_figure',
    'bode_plot',
    'compare',
    'compare_figure',
    'compare_plot',
    'delayest',
    'export_mat',
    'fit_percent',
    'fpe',
    'iv4',
    'least_squares',
    'load_data',
    'load_model',
    'make_orders',
    'mdl',
    'merge',
    'model_from_dict',
    'model_to_dict',
    'oe',
    'resid',
    'resid_figure',
    'resid_plot',
    'rls_arx',
    'save_model',
    'selstruc',
]
