"""Small studies shared by the study tests (short runs: a loaded 2-core machine)."""

from __future__ import annotations

import pytest
import yaml

SMALL = {
    'name': 'small',
    'duration': 0.3,
    'seed': 7,
    'repeats': 2,
    'success': {'window': 0.1, 'rms': 2.0e-4},
    'fixed': {'params': 'maggy_v2'},
    'grid': {'controller': ['lqr', 'pd'], 'x0.x': [0.0, 1.2e-3]},
    'random': {'plant.polarization': {'normal': {'mean': 0.0, 'std': 0.01}}},
}


@pytest.fixture
def small_study(tmp_path):
    """Path of a study file of 8 runs of 0.3 s."""
    path = tmp_path / 'small.yaml'
    path.write_text(yaml.safe_dump(SMALL, sort_keys=False))
    return path
