"""The closed loop without ROS: plants, the control loop and its observers.

One loop (:class:`ControlLoop`: read, estimate, control, write, observers) is
what every caller runs: :class:`~maglev_ros.control.ClosedLoop` in
simulation studies, the nodes, the lab, the tests and the benchmarks.
"""

from .control_loop import MAX_COMMAND_DELAY, ControlLoop, LoopSample
from .observers import Observer, ObserverSet, ObserverThread
from .plant import Plant, SampleBlock
from .simulated import SimulatedPlant

__all__ = [
    'MAX_COMMAND_DELAY',
    'ControlLoop',
    'LoopSample',
    'Observer',
    'ObserverSet',
    'ObserverThread',
    'Plant',
    'SampleBlock',
    'SimulatedPlant',
]
