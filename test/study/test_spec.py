"""Study files: what is accepted, and every problem named by file and key."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from maglev_ros.study import StudyError, load_study, plan_runs, study_from_mapping
from maglev_ros.study.spec import SuccessCriterion


def _spec(**changes):
    return study_from_mapping({'duration': 1.0, **changes}, 'f.yaml')


def test_a_full_study_is_read_in_file_order():
    spec = _spec(
        name='s',
        seed=3,
        repeats=2,
        success={'rms': 2e-4},
        fixed={'params': 'maggy_v4', 'sensor.delay': 1},
        grid={'controller': ['lqr', 'pd'], 'x0.x': {'start': 0, 'stop': 1e-3, 'num': 3}},
        random={'plant.mass': {'uniform': {'low': -0.1, 'high': 0.1}}},
    )
    assert spec.keys == ['params', 'sensor.delay', 'controller', 'x0.x', 'plant.mass']
    assert spec.grid['x0.x'] == (0.0, 0.0005, 0.001)
    assert spec.n_runs == 2 * 3 * 2
    assert spec.success == SuccessCriterion(bound=3e-3, window=0.3, rms=2e-4)
    # the stored form reads back to the same study
    again = study_from_mapping(spec.to_mapping(), 'g.yaml')
    assert again.fingerprint() == spec.fingerprint()
    assert _spec(seed=4).fingerprint() != _spec(seed=5).fingerprint()


@pytest.mark.parametrize(
    ('changes', 'match'),
    [
        (
            {'grid': {'plant.polarisation': [0.1]}},
            r'grid.plant.polarisation: unknown parameter \(did you mean plant.polarization',
        ),
        ({'fixed': {'sensor.noise': -1e-5}}, r'f.yaml: fixed.sensor.noise: must be >= 0'),
        (
            {'grid': {'sensor.quantization': [1e-4, -1e-4]}},
            r'grid.sensor.quantization: must be >= 0',
        ),
        ({'grid': {'x0.x': []}}, r'grid.x0.x: empty grid'),
        ({'grid': {'x0.x': [1e-3, 1e-3]}}, r'grid.x0.x: repeated values'),
        (
            {'grid': {'x0.x': {'start': 0, 'stop': 1}}},
            r'grid.x0.x: a range needs exactly start, stop and num',
        ),
        (
            {'random': {'controller': {'normal': {'mean': 0, 'std': 1}}}},
            r'random.controller: not a number',
        ),
        (
            {'random': {'x0.x': {'gauss': {'mean': 0, 'std': 1}}}},
            r'random.x0.x: expected \{normal',
        ),
        (
            {'random': {'x0.x': {'uniform': {'low': 1, 'high': 1}}}},
            r'random.x0.x.uniform: high must exceed low',
        ),
        ({'fixed': {'x0.x': 0.0}, 'grid': {'x0.x': [0.0]}}, r'grid.x0.x: already set under fixed'),
        ({'fixed': {'sensor.delay': 2}}, r'fixed.sensor.delay: expected one of 0, 1'),
        ({'fixed': {'loop.command_delay': 21}}, r'fixed.loop.command_delay: must be from 0 to 20'),
        ({'fixed': {'estimator.filter': 'kf'}}, r'fixed.estimator.filter: unknown parameter'),
        ({'fixed': {'plant.mass': -1.0}}, r'fixed.plant.mass: must be above -1'),
        ({'fixed': {'params': 'maggy_v9'}}, r'fixed.params: expected maggy_v2 or maggy_v4'),
        (
            {'fixed': {'controller.integral': 1}},
            r'fixed.controller.integral: expected true or false',
        ),
        ({'repeats': 0}, r'f.yaml: repeats: expected an integer >= 1'),
        ({'success': {'rms': 0}}, r'success.rms: must be positive'),
        ({'success': {'settle': 0.1}}, r'success.settle: unknown key'),
        ({'duration': -1}, r'duration: must be positive'),
        ({'grids': {}}, r'f.yaml: grids: unknown key'),
    ],
)
def test_a_bad_study_names_file_and_key(changes, match):
    with pytest.raises(StudyError, match=match):
        _spec(**changes)


def test_a_missing_duration_and_bad_yaml(tmp_path):
    with pytest.raises(StudyError, match=r'f.yaml: duration: missing'):
        study_from_mapping({'grid': {}}, 'f.yaml')
    path = tmp_path / 'bad.yaml'
    path.write_text('duration: [1\n')
    with pytest.raises(StudyError, match=r'bad.yaml: invalid YAML'):
        load_study(path)
    with pytest.raises(StudyError, match=r'study file not found'):
        load_study(tmp_path / 'none.yaml')


def test_the_documented_study_and_the_shipped_studies_are_valid():
    docs = Path(__file__).resolve().parents[2] / 'docs'
    text = (docs / 'studies.md').read_text()
    block = re.search(r'## A study file\n\n(?:<!--.*?-->\n)?```yaml\n(.*?)```', text, re.S).group(
        1
    )
    assert plan_runs(study_from_mapping(yaml.safe_load(block), 'studies.md'))
    files = sorted((docs / 'studies').glob('*.yaml'))
    assert len(files) >= 4
    for path in files:
        assert plan_runs(load_study(path)), path
