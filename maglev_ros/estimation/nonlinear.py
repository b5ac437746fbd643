"""What the nonlinear filters (EKF, UKF) share: the fast model's compiled f and h."""

from __future__ import annotations

import numpy as np

from .filter_model import base_reading

__all__ = ['FAST_RIM_POINTS', 'FilterModel', 'compiled_arguments', 'require_fast_field']


def require_fast_field(model, filter_name: str) -> None:
    """Refuse a model whose field is not the fast (compiled) one.

    Parameters
    ----------
    model : MaggyModel
        The model the filter would run.
    filter_name : str
        The filter's short name for the message (``'EKF'``, ``'UKF'``).

    Raises
    ------
    ValueError
        The model's field option is not ``'fast'``.
    """
    if model.options.field != 'fast':
        raise ValueError(
            f'the {filter_name} needs the fast field model, got {model.options.field!r}'
        )


def compiled_arguments(model) -> tuple[tuple, tuple]:
    """Arguments of the physics core's compiled dynamics f and measurement h.

    Parameters
    ----------
    model : MaggyModel
        A model with the fast field.

    Returns
    -------
    f_args : tuple
        ``(sources, coils, rim, parameters, work)`` for ``rk4_sample``.
    h_args : tuple
        ``(sources, coils, sensors, magnet, work)`` for ``fast_measurement``.
    """
    src, coil, rim, par, work = model.fast_arguments()
    _, _, sens, mag, _ = model.measurement_arguments()
    return (src, coil, rim, par, work), (src, coil, sens, mag, work)


#: Rim points of the fast prediction's force and torque (the model's: 32; a multiple
#: of 4 keeps the mirror-pair sums). The rim integral of a smooth periodic field
#: converges exponentially in the points: against 32, at 30 random states within
#: about 2 mm and 0.05 rad (1 sigma) of the equilibrium, 20 points change the
#: acceleration by at most 3.4e-5 m/s^2 (V2) and 0.023 m/s^2 (V4), 24 by 5e-7 and
#: 3e-4, 16 by 0.0013 and 0.35 (the process noise: 0.1 m/s^2 a sample); at the
#: equilibrium 20 points leave 2.8e-8 (V2) and 1.9e-5 m/s^2 (V4).
FAST_RIM_POINTS = 20


class FilterModel:
    """The compiled f and h a nonlinear filter runs (see :mod:`.filter_model`).

    Parameters
    ----------
    model : MaggyModel
        A model with the fast field (the filter's private copy: its scratch
        space is not shared).

    Attributes
    ----------
    f_args : tuple
        ``(src, coil, rim, par, work)``: ``physics.kernels.fast_dynamics``'s.
    fast_f_args : tuple
        The same with :data:`FAST_RIM_POINTS` rim points (when the model has
        more): the fast prediction's f.
    h_args : tuple
        ``(y0, G, sens, mag, own_src, own_coil, work)``:
        :func:`.filter_model.magnet_reading`'s.
    """

    def __init__(self, model):
        self.f_args = tuple(model.fast_arguments())
        self.fast_f_args = self.f_args
        if model.rim_points > FAST_RIM_POINTS:
            coarse = model.with_options(rim_points=FAST_RIM_POINTS)
            self.fast_f_args = tuple(coarse.fast_arguments())
        _, _, sens, mag, work = model.measurement_arguments()
        y0, G = base_reading(model)
        own_src = np.zeros((1, 6))
        own_src[0, 3] = mag[0]
        own_src[0, 4] = mag[1]
        self.h_args = (y0, G, sens, mag, own_src, np.full(1, -1, dtype=np.int64), work)
