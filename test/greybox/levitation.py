"""Levitation records of a perturbed Maggy V2 for the dynamic calibration tests.

The plant's magnet is heavier and weaker than nominal (mass +4 %,
polarisation -3 %); the nominal estimator and LQR hold it in the ROS-free
closed loop (:func:`maglev_ros.control.closed_loop.make_closed_loop`: sensor
noise 0.1 mT, 0.098 mT quantisation, one sample of sensor delay, coil
electrics) while a random binary excitation is added to the command.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.estimation import EstimatorConfig
from maglev_ros.excitation.signals import random_binary
from maglev_ros.greybox import LevitationExperiment, parameter_vector
from maglev_ros.physics import load_parameters

TS = 2e-4  # s (5 kHz, the controller's default rate)
TRUTH = {'magnet.mass': 0.077 * 1.04, 'magnet.polarization': -1.0 * 0.97}
#: The loop's estimator, part of the experiment: these records and the fits' bounds were
#: made with the tilt noise of 0.5 rad/s^2 (the estimator's default until the model
#: mismatch fix of issue 9 raised it to 50; the output-error fit's 3 % bound on 0.4 s is
#: sensitive to the loop's noise-driven motion: 3.2 % on the mass with 50)
RECORD_ESTIMATOR = EstimatorConfig(angular_acceleration_noise=0.5)


@lru_cache(maxsize=1)
def nominal_vector():
    return parameter_vector(load_parameters('maggy_v2'))


@lru_cache(maxsize=1)
def plant_parameters():
    return nominal_vector().apply(TRUTH)


def excitation(duration: float, amplitude: float = 0.05, seed: int = 0) -> np.ndarray:
    """Independent random binary currents per coil, A, shape (N, 4)."""
    n = int(round(duration / TS))
    return np.column_stack(
        [random_binary(n, amplitude, (0.0, 0.2), seed=seed + j) for j in range(4)]
    )


@lru_cache(maxsize=2)
def levitation_record(duration: float = 2.0, seed: int = 1):
    """Run the loop; return (LevitationExperiment, LoopResult)."""
    loop = make_closed_loop(
        nominal_vector().base, plant=plant_parameters(), seed=seed, estimator=RECORD_ESTIMATOR
    )
    result = loop.run(duration, excitation=excitation(duration, seed=10 * seed))
    assert not result.crashed, result.reason
    exp = LevitationExperiment(result.currents, result.readings, 'simulated levitation', TS)
    return exp, result
