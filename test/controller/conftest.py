"""Shared fixtures: models and linearisations, built once per session.

(This directory is not named ``control``: with pytest's rootdir on sys.path a test
package of that name would shadow python-control.)
"""

import pytest

from maglev_ros.physics import linearize, make_model


@pytest.fixture(scope='session')
def v2():
    return make_model('maggy_v2')


@pytest.fixture(scope='session')
def v2_linear(v2):
    return linearize(v2)


@pytest.fixture(scope='session')
def v4():
    return make_model('maggy_v4')


@pytest.fixture(scope='session')
def v4_linear(v4):
    return linearize(v4)
