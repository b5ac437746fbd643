"""The one place a study touches the closed loop: study values in, a LoopResult out.

Everything else in :mod:`maglev_ros.study` speaks of study parameters and
result rows; only this module knows how the ROS-free closed loop
(:func:`~maglev_ros.control.closed_loop.make_closed_loop`,
``ClosedLoop.run``, :class:`~maglev_ros.control.closed_loop.LoopResult`) is
built and run, so a new loop is a change here.

Building a loop (linearisation, LQR design, filter) costs about as much as a
second of simulation, so each worker process keeps the loops it built and
reuses one for every run of the same set-up; a run only sets the noise seed
and the command delay, and ``run`` resets the simulator (which reseeds its
noise), the estimator and the controller. A reused loop gives the same
numbers as a fresh one (checked by the tests).
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from .parameters import PARAMETERS

__all__ = ['LoopSetup', 'check_setup', 'loop_setup', 'simulate', 'LOOP_CACHE_SIZE']

#: Loops kept per process (one per distinct set-up).
LOOP_CACHE_SIZE = 16
_PLANT_KEYS = (
    'plant.polarization',
    'plant.mass',
    'plant.coil_resistance',
    'plant.sensor_dx',
    'plant.sensor_dy',
    'plant.sensor_dz',
    'plant.sensor_offset_x',
    'plant.sensor_offset_y',
    'plant.sensor_offset_z',
)
_X0_INDEX = {'x0.x': 0, 'x0.y': 1, 'x0.z': 2, 'x0.alpha': 3, 'x0.beta': 4}


@dataclass(frozen=True)
class LoopSetup:
    """Everything that decides how a loop is built (hashable: the cache key).

    Attributes
    ----------
    params : str
        Parameter set the estimator and controller believe.
    controller : ControllerConfig
    estimator : EstimatorConfig or None
        None for the PD.
    noise, quantization : float
        T rms, T per LSB.
    sensor_delay : int
        Samples.
    plant : tuple of float
        The ``plant.*`` values in ``_PLANT_KEYS`` order (all 0: the believed plant).
    """

    params: str
    controller: Any
    estimator: Any
    noise: float
    quantization: float
    sensor_delay: int
    plant: tuple[float, ...]


def _value(values: dict[str, Any], key: str) -> Any:
    return values.get(key, PARAMETERS[key].default)


def loop_setup(values: dict[str, Any]) -> LoopSetup:
    """Return the set-up of a run's values (defaults for what they do not set).

    Parameters
    ----------
    values : dict
        Study key to value.

    Raises
    ------
    ValueError
        The controller or estimator settings do not fit together.
    """
    from ..control import ControllerConfig
    from ..estimation import EstimatorConfig

    delay = _value(values, 'sensor.delay')
    ctrl = {k.split('.', 1)[1]: v for k, v in values.items() if k.startswith('controller.')}
    controller = ControllerConfig(mode=_value(values, 'controller'), sensor_delay=delay, **ctrl)
    estimator = None
    if controller.mode == 'lqr':
        est = {k.split('.', 1)[1]: v for k, v in values.items() if k.startswith('estimator.')}
        estimator = EstimatorConfig(
            filter=_value(values, 'estimator'),
            sample_rate=controller.sample_rate,
            sensor_delay=delay,
            **est,
        )
    return LoopSetup(
        params=_value(values, 'params'),
        controller=controller,
        estimator=estimator,
        noise=_value(values, 'sensor.noise'),
        quantization=_value(values, 'sensor.quantization'),
        sensor_delay=delay,
        plant=tuple(float(_value(values, k)) for k in _PLANT_KEYS),
    )


def check_setup(values: dict[str, Any]) -> None:
    """Raise ValueError when a run's values cannot make a loop (without building it).

    Parameters
    ----------
    values : dict
        Study key to value.
    """
    loop_setup(values)


@lru_cache(maxsize=4)
def _believed(params: str):
    from ..physics import linearize, make_model

    model = make_model(params)
    return model, linearize(model)


def _plant(model, changes: tuple[float, ...]):
    """Return the simulated plant: the believed one with the ``plant.*`` errors (None if none)."""
    if not any(changes):
        return None
    from ..physics import MaggyModel

    c = dict(zip(_PLANT_KEYS, changes, strict=True))
    p = model.params
    magnet = dataclasses.replace(
        p.magnet,
        polarization=p.magnet.polarization * (1.0 + c['plant.polarization']),
        mass=p.magnet.mass * (1.0 + c['plant.mass']),
    )
    coils = dataclasses.replace(
        p.coils, resistance=p.coils.resistance * (1.0 + c['plant.coil_resistance'])
    )
    shift = np.array([c['plant.sensor_dx'], c['plant.sensor_dy'], c['plant.sensor_dz']])
    offset = np.array(
        [c['plant.sensor_offset_x'], c['plant.sensor_offset_y'], c['plant.sensor_offset_z']]
    )
    sensors = tuple(
        dataclasses.replace(s, position=s.position + shift, offset=s.offset + offset)
        for s in p.sensors
    )
    # the fast field's solenoid factor stays the believed one: only the named errors differ
    plant = p.replace(
        magnet=magnet,
        coils=coils,
        sensors=sensors,
        solenoid_radius_correction=model.correction,
    )
    return MaggyModel(plant, model.options)


_loops: OrderedDict[LoopSetup, Any] = OrderedDict()


def _loop(setup: LoopSetup):
    loop = _loops.pop(setup, None)
    if loop is None:
        from ..control.closed_loop import make_closed_loop

        model, linear = _believed(setup.params)
        loop = make_closed_loop(
            model,
            estimator=setup.estimator,
            controller=setup.controller,
            plant=_plant(model, setup.plant),
            noise=setup.noise,
            quantization=setup.quantization,
            sensor_delay=setup.sensor_delay,
            linear=linear,
        )
    _loops[setup] = loop
    while len(_loops) > LOOP_CACHE_SIZE:
        _loops.popitem(last=False)
    return loop


def simulate(values: dict[str, Any], seed: int, duration: float):
    """Run the closed loop of a study run.

    Parameters
    ----------
    values : dict
        Study key to value (defaults for the rest).
    seed : int
        Noise seed.
    duration : float
        s of simulated time.

    Returns
    -------
    LoopResult
        The run (it stops at a crash); ``z_eq`` is the plant's equilibrium.
    """
    loop = _loop(loop_setup(values))
    delay = _value(values, 'loop.command_delay')
    loop.command_delay = loop.controller.config.command_delay if delay < 0 else delay
    loop.simulator.seed = seed
    x0 = loop.simulator.model.hover_state(loop.z_eq)
    for key, i in _X0_INDEX.items():
        x0[i] += _value(values, key)
    return loop.run(duration, x0=x0)
