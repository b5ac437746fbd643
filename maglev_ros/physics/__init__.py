"""Physics of the Maggy platform (ROS-free).

Fields of loops, current sheets and filament solenoids; force and torque on
the levitating magnet; the 12-state dynamics f(x, u) and sensor model h(x, u);
equilibria, linearisation and simulation. Specified in ``maggy-model.md``.
"""

from .discretization import zoh
from .equilibria import Equilibrium, find_equilibria, solenoid_radius_correction, vertical_force
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
)
from .parameters import PRESETS, MaggyParameters, ParameterError, load_parameters
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
    'zoh',
]
