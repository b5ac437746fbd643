"""Shared fixtures: models, linearisations and recorded open-loop data, built once."""

import pytest

from .open_loop import open_loop_run


@pytest.fixture(scope='session')
def v2_data(v2, v2_linear):
    """0.15 s of noisy, quantised, delayed readings and coil currents from a small offset.

    Returns (readings (N, 9), currents (N, 4), true states (N, 12)).
    """
    return open_loop_run(v2, v2_linear.x_eq)
