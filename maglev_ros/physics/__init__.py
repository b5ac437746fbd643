"""Physics of the Maggy platform (ROS-free).

Fields of loops, current sheets and filament solenoids; force and torque on
the levitating magnet; the 12-state dynamics f(x, u) and sensor model h(x, u);
equilibria, linearisation and simulation; a simulation session paces the
simulator in real time or lockstep (``session``). Specified in ``maggy-model.md``.
"""

from .discretization import zoh
from .equilibria import Equilibrium, find_equilibria, rest_state, vertical_force
from .linearization import (
    LinearModel,
    controllability_rank,
    linearize,
    observability_rank,
)
from .loop import MU0, loop_field, loop_field_cylindrical
from .model import (
    FIELD_MODELS,
    KINEMATICS,
    STATE_NAMES,
    TORQUE_MODES,
    MaggyModel,
    ModelOptions,
    make_model,
    solenoid_radius_correction,
)
from .parameters import PRESETS, MaggyParameters, ParameterError, load_parameters
from .session import CommandError, SampleBatch, SimulationSession
from .sheet import sheet_field
from .simulation import (
    CoilDynamics,
    SensorEffects,
    SensorFreeze,
    SimulationCrashedError,
    SimulationResult,
    Simulator,
    simulate_reference,
)

__all__ = [
    'MU0',
    'FIELD_MODELS',
    'TORQUE_MODES',
    'KINEMATICS',
    'STATE_NAMES',
    'PRESETS',
    'ParameterError',
    'MaggyParameters',
    'load_parameters',
    'loop_field',
    'loop_field_cylindrical',
    'sheet_field',
    'ModelOptions',
    'MaggyModel',
    'make_model',
    'Equilibrium',
    'vertical_force',
    'find_equilibria',
    'solenoid_radius_correction',
    'rest_state',
    'LinearModel',
    'linearize',
    'controllability_rank',
    'observability_rank',
    'CoilDynamics',
    'SensorEffects',
    'SensorFreeze',
    'SimulationResult',
    'SimulationCrashedError',
    'Simulator',
    'simulate_reference',
    'CommandError',
    'SampleBatch',
    'SimulationSession',
    'zoh',
]
