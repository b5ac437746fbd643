"""Robustness studies of the closed loop: Monte Carlo and region-of-attraction maps.

A study file (:mod:`.spec`) names what is fixed, varied on a grid and drawn
at random; :func:`plan_runs` turns it into seeded runs; :func:`run_study`
does them on a back end (:class:`SerialBackend`, or :class:`DaskBackend`:
local worker processes or a Dask cluster), keeping a journal so an
interrupted study resumes; :mod:`.results` writes the table and the
summary, :mod:`.plots` the figures. Each run is the package's ROS-free
closed loop (:mod:`.loop_adapter`).
"""

from .backends import DaskBackend, SerialBackend, local_worker_count
from .execute import StudyInterrupted, StudyRun, run_study
from .parameters import PARAMETERS, StudyError, StudyParameter
from .plots import plot_study
from .results import Journal, read_table, summary, write_table
from .runner import METRICS, run_task
from .sampling import RunTask, plan_runs
from .spec import StudySpec, SuccessCriterion, load_study, study_from_mapping

__all__ = [
    'DaskBackend',
    'Journal',
    'METRICS',
    'PARAMETERS',
    'RunTask',
    'SerialBackend',
    'StudyError',
    'StudyInterrupted',
    'StudyParameter',
    'StudyRun',
    'StudySpec',
    'SuccessCriterion',
    'load_study',
    'local_worker_count',
    'plan_runs',
    'plot_study',
    'read_table',
    'run_study',
    'run_task',
    'study_from_mapping',
    'summary',
    'write_table',
]
