"""The closed loop without ROS: plants, the control loop and its observers.

One loop (:class:`ControlLoop`: read, estimate, control, write, observers) is
what every caller runs: :class:`~maglev_ros.control.ClosedLoop` in
simulation studies, the nodes, the lab, the tests and the benchmarks. The lab
session (:func:`run_session`: settle, excite, record exactly N samples) runs
it on any plant (simulated, paced, a :class:`BoardPlant`), its recorded
samples going to observers (:class:`BagRecorder`, :class:`OnlineIdentifier`).
"""

from .bag_recorder import BagRecorder
from .board import BoardPlant
from .control_loop import MAX_COMMAND_DELAY, ControlLoop, LoopSample
from .lab import LabSettings, build_lab_loop, lab_plan
from .observers import Observer, ObserverSet, ObserverThread
from .online_identifier import OnlineEstimate, OnlineIdentifier
from .open_loop import OpenLoop
from .paced import PacedSimulatedPlant
from .plant import Plant, SampleBlock
from .session import SessionPlan, SessionResult, WindowSample, run_session
from .simulated import SimulatedPlant
from .simulated_setup import SimulatedLoopSettings, build_simulated_loop

__all__ = [
    'MAX_COMMAND_DELAY',
    'BagRecorder',
    'BoardPlant',
    'ControlLoop',
    'LabSettings',
    'LoopSample',
    'Observer',
    'ObserverSet',
    'ObserverThread',
    'OnlineEstimate',
    'OnlineIdentifier',
    'OpenLoop',
    'PacedSimulatedPlant',
    'Plant',
    'SampleBlock',
    'SessionPlan',
    'SessionResult',
    'SimulatedLoopSettings',
    'SimulatedPlant',
    'WindowSample',
    'build_lab_loop',
    'build_simulated_loop',
    'lab_plan',
    'run_session',
]
