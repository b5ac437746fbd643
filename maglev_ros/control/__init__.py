"""Levitation control (ROS-free): LQR on the estimate, the firmware's PD, the closed loop.

``make_controller`` chooses by :attr:`ControllerConfig.mode`; :mod:`.closed_loop`
steps simulator, estimator and controller as the nodes do.
"""

from .config import MODES, ControllerConfig, ControllerConfigError, load_controller_config
from .design import LqrDesign, design_lqr, steady_state
from .lqr import LqrController
from .pd import PdController
from .safety import ControllerStatus, Watchdog

__all__ = [
    'MODES',
    'ControllerConfig',
    'ControllerConfigError',
    'load_controller_config',
    'LqrDesign',
    'design_lqr',
    'steady_state',
    'LqrController',
    'PdController',
    'ControllerStatus',
    'Watchdog',
    'make_controller',
]


def make_controller(model, config: ControllerConfig | None = None, linear=None):
    """Build the controller ``config.mode`` names (LQR or PD).

    Parameters
    ----------
    model : MaggyModel
        The model the controller believes.
    config : ControllerConfig, optional
    linear : LinearModel, optional
        Linearisation about the equilibrium, to share one computation.
    """
    config = config or ControllerConfig()
    if config.mode == 'pd':
        return PdController(model, config, linear)
    return LqrController(model, config, linear)
