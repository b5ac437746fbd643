"""maglev-sysid on closed-loop data of the open-loop-unstable Maggy plant (LQR + Kalman filter)."""

import json

import numpy as np
import pytest
from sysid.maglev_loop import TS, plant, simulate

from maglev_ros.cli.sysid import main

MODELS = ['--arx', 4, 4, 1, '--armax', 4, 4, 4, 1, '--oe', 4, 4, 1, '--bj', 4, 2, 2, 4, 1]


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp('loop')
    paths = {}
    for name, excitation in (('quiet', 0.0), ('excited', 0.5)):
        data, r = simulate(8000, 3, excitation)
        paths[name] = folder / f'{name}.npz'
        np.savez(
            paths[name], y=data.y, u=data.u, r=r, Ts=TS, output_names=['Bx_0'],
            input_names=['ux'], output_units=['T'], input_units=['A'],
        )  # fmt: skip
    return paths


def test_without_excitation_no_model_is_ok_and_the_loop_is_named(files, capsys):
    code, out, err = run([files['quiet'], *MODELS], capsys)
    assert code == 1, err
    assert 'warning: closed loop: ux reacts to Bx_0' in out and 'no external excitation' in out
    assert '--instruments' in out and '--horizon' in out
    summary = out[out.index('Summary') :]
    assert ' ok' not in summary and summary.count('no excitation - not usable') == 4
    code, out, _ = run([files['quiet'], *MODELS, '--json'], capsys)
    result = json.loads(out)
    assert result['closed_loop'] and not result['feedback']['informative']
    assert result['warnings'] and result['feedback']['advice']
    for m in result['models']:
        assert m['status'] == 'no excitation' and not m['usable']
        assert len(m['kstep_validation']) == 1 and m['kstep_horizon'] == 5


def test_with_excitation_iv_on_it_recovers_the_unstable_pole(files, capsys):
    argv = [files['excited'], '--iv', 4, 4, 1, '--instruments', 'r', '--oe', 4, 4, 1, '--json']
    code, out, err = run(argv, capsys)
    result = json.loads(out)
    assert result['closed_loop'] and result['feedback']['informative']
    iv, oe = result['models']
    assert iv['status'] == 'unstable' and iv['usable'], iv['reason']
    assert 'instrument independence ok' in iv['residuals_summary']
    assert oe['status'] == 'closed-loop bias' and not oe['usable'] and code == 1
    a = np.array(iv['polynomials']['A'][0][0])
    pole = float(np.max(np.log(np.roots(a).astype(complex)).real) / TS)
    truth = plant()[3]  # about +54.5 1/s
    assert abs(pole - truth) < 0.1 * truth, (pole, truth)
    assert iv['fit_validation'] == [None] and iv['kstep_validation'][0] is not None
