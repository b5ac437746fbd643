"""Parameter sets: the shipped presets load; bad files are rejected naming file and key."""

import copy

import numpy as np
import pytest
import yaml

from maglev_ros.physics.parameters import (
    ParameterError,
    load_parameters,
    parameters_from_mapping,
    preset_path,
)


@pytest.mark.parametrize('name', ['maggy_v2', 'maggy_v4'])
def test_presets_load_as_immutable_typed_objects(name):
    params = load_parameters(name)
    assert params.name == name
    assert params.solenoids.count == 4 and params.permanent_magnets.count == 4
    assert len(params.sensors) == 3
    np.testing.assert_allclose(params.magnet.inertia, [6.1686e-6, 6.1686e-6, 1.1274e-5])
    with pytest.raises(ValueError, match='read-only'):
        params.solenoids.radius[0] = 1.0
    with pytest.raises(AttributeError):
        params.name = 'other'


def test_v4_corners_are_at_sqrt_half_of_35_mm():
    centers = load_parameters('maggy_v4').permanent_magnets.centers
    np.testing.assert_allclose(np.abs(centers[:, :2]), np.sqrt(0.5) * 0.035, rtol=1e-15)


def test_inertia_is_overridable():
    params = load_parameters('maggy_v2').with_inertia([1e-5, 1e-5, 2e-5])
    np.testing.assert_array_equal(params.magnet.inertia, [1e-5, 1e-5, 2e-5])
    with pytest.raises(ParameterError, match='inertia'):
        load_parameters('maggy_v2').with_inertia([1e-5, -1.0, 2e-5])


@pytest.fixture
def document():
    with open(preset_path('maggy_v2'), encoding='utf-8') as stream:
        return yaml.safe_load(stream)


def _write(tmp_path, doc):
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize(
    'mutate, key',
    [
        (lambda d: d['solenoids'].pop('turns'), r'solenoids\.turns: missing key'),
        (lambda d: d['levitating_magnet'].pop('mass'), r'levitating_magnet\.mass: missing key'),
        (lambda d: d.pop('workspace'), r'workspace: missing key'),
        (
            lambda d: d['solenoids']['radius'].pop(),
            r'solenoids\.radius: expected 4 values .*got 3',
        ),
        (
            lambda d: d['permanent_magnets']['y'].append(0.0),
            r'permanent_magnets\.y: expected 4 values \(as many as permanent_magnets\.x\), got 5',
        ),
        (lambda d: d['sensors'][0]['position'].pop(), r'sensors\[0\]\.position: expected 3'),
        (
            lambda d: d['solenoids']['radius'].__setitem__(1, 0.0),
            r'solenoids\.radius\[1\]: must be',
        ),
        (
            lambda d: d['solenoids']['turns'].__setitem__(2, -480),
            r'solenoids\.turns\[2\]: must be',
        ),
        (
            lambda d: d['levitating_magnet'].__setitem__('mass', 0),
            r'levitating_magnet\.mass: must be',
        ),
        (
            lambda d: d['levitating_magnet'].__setitem__('radius', -0.02),
            r'levitating_magnet\.radius',
        ),
        (
            lambda d: d['permanent_magnets'].__setitem__('colour', 'red'),
            r'permanent_magnets\.colour: unknown key',
        ),
        (lambda d: d.__setitem__('gravity', 9.81), r'gravity: unknown key'),
        (lambda d: d['coils'].__setitem__('resistance', 'three'), r'coils\.resistance: expected'),
        (lambda d: d['workspace'].__setitem__('max', [0.06, 0.06, -1.0]), r'workspace: max must'),
    ],
)
def test_bad_files_name_the_file_and_the_key(tmp_path, document, mutate, key):
    doc = copy.deepcopy(document)
    mutate(doc)
    path = _write(tmp_path, doc)
    with pytest.raises(ParameterError, match=rf'bad\.yaml: {key}'):
        load_parameters(path)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ParameterError, match=r'nothere\.yaml: parameter file not found'):
        load_parameters(tmp_path / 'nothere.yaml')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('magnet:\n  radius: 1\nsolenoids: [unclosed\nother: 2\n')
    # one line that keeps PyYAML's position (the CLI prints only the first line)
    with pytest.raises(
        ParameterError, match=r'broken\.yaml: invalid YAML, line 4, column 6: '
    ) as err:
        load_parameters(broken)
    assert '\n' not in str(err.value)
    with pytest.raises(ParameterError, match=r'<memory>: expected a mapping'):
        parameters_from_mapping([1, 2, 3])


def test_sensor_rotation_must_be_a_rotation(document):
    doc = copy.deepcopy(document)
    doc['sensors'][1]['rotation'] = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]
    with pytest.raises(ParameterError, match=r'sensors\[1\]\.rotation: must be a proper rotation'):
        parameters_from_mapping(doc, 'doc.yaml')
