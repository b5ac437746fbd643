"""Shared fixtures of the physics tests: models are built once per session."""

import pytest

from maglev_ros.physics.equilibria import find_equilibria
from maglev_ros.physics.model import make_model


@pytest.fixture(scope='session', params=['maggy_v2', 'maggy_v4'])
def fast_model(request):
    return make_model(request.param)


@pytest.fixture(scope='session')
def v2_equilibrium(v2):
    return v2.hover_state(find_equilibria(v2)[0].z)
