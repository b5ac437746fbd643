"""maglev-sysid reads a bag directly, with the bag converter's channel options."""

import json
from dataclasses import replace

import numpy as np
import pytest
from bags.recordings import COMMAND, SENSOR, lockstep_data, write_lockstep_bag
from scipy.signal import lfilter

from maglev_ros.cli.sysid import main


@pytest.fixture(scope='module')
def arx_bag(tmp_path_factory):
    # field x follows y[k] = 0.8 y[k-1] + 0.5e-3 u[k-1] (T, u in A) from the x+ command
    run = lockstep_data(4000, seed=5)
    y = lfilter([0.0, 0.5e-3], [1.0, -0.8], run.command[:, 0])
    field = run.field.copy()
    field[:, 0] = y
    return write_lockstep_bag(tmp_path_factory.mktemp('bag') / 'arx', replace(run, field=field))


@pytest.fixture(scope='module')
def joint_bag(tmp_path_factory):
    """The same run with the commands as JointState, stamped with their samples."""
    run = lockstep_data(4000, seed=5)
    field = run.field.copy()
    field[:, 0] = lfilter([0.0, 0.5e-3], [1.0, -0.8], run.command[:, 0])
    path = tmp_path_factory.mktemp('bag') / 'joint'
    return write_lockstep_bag(path, replace(run, field=field), stamped_commands=True)


@pytest.mark.parametrize('which', ['Float64MultiArray', 'JointState'])
def test_sysid_identifies_from_a_bag(arx_bag, joint_bag, capsys, which):
    argv = [
        str(arx_bag if which == 'Float64MultiArray' else joint_bag),
        '--output',
        f'{SENSOR}:magnetic_field.x',
        '--input',
        f'{COMMAND}:data[0]',
        '--arx',
        '1',
        '1',
        '1',
        '--json',
    ]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    model = result['models'][0]
    assert result['data']['N'] == 4000 and result['data']['Ts'] == pytest.approx(2e-4)
    np.testing.assert_allclose(model['theta'], [-0.8, 0.5e-3], rtol=1e-9)
    assert np.min(model['fit_validation']) > 99.9


def test_a_bag_needs_channels(arx_bag, capsys):
    assert main([str(arx_bag), '--arx', '1', '1', '1']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'is a bag: choose channels with --output' in err[0]
