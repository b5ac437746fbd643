"""maglev-sysid --instruments on a bag: the excitation read with the channel syntax."""

import json
from dataclasses import replace

import numpy as np
from bags.recordings import COMMAND, SENSOR, lockstep_data, write_lockstep_bag

from maglev_ros.cli.sysid import main

THETA_CL = np.array([-1.5, 0.7, 0.5, 0.2])  # ARX 2 2 1: a1 a2 b1 b2


def simulate_loop(N, seed):
    """Plant y0 = (0.5 q^-1 + 0.2 q^-2)/(1 - 1.5 q^-1 + 0.7 q^-2) u, y = y0 + v, u = -y/2 + r."""
    rng = np.random.default_rng(seed)
    r = rng.choice([-1.0, 1.0], N)
    v = 0.5 * rng.standard_normal(N)
    y0, y, u = np.zeros(N), np.zeros(N), np.zeros(N)
    for t in range(N):
        if t >= 2:
            y0[t] = 1.5 * y0[t - 1] - 0.7 * y0[t - 2] + 0.5 * u[t - 1] + 0.2 * u[t - 2]
        y[t] = y0[t] + v[t]
        u[t] = -0.5 * y[t] + r[t]
    return y, u, r


def test_bag_instruments_channel(tmp_path, capsys):
    y, u, r = simulate_loop(8000, 2)
    run = lockstep_data(8000, seed=3)
    field, command = run.field.copy(), run.command.copy()
    field[:, 0] = 1e-3 * y  # T
    command[:, 0], command[:, 1] = u, -u  # antisymmetric x pair
    command[:, 2] = 0.25 * r  # the excitation, recorded on a spare element
    bag = write_lockstep_bag(tmp_path / 'loop', replace(run, field=field, command=command))
    argv = [
        str(bag),
        '--output',
        f'{SENSOR}:magnetic_field.x',
        '--input',
        f'ux=0.5*{COMMAND}:data[0]-0.5*{COMMAND}:data[1]',
        '--instruments',
        f'r=4*{COMMAND}:data[2]',
        '--arx',
        '2',
        '2',
        '1',
        '--iv',
        '2',
        '2',
        '1',
        '--json',
    ]
    code = main(argv)
    result = json.loads(capsys.readouterr().out)
    assert result['closed_loop'] and result['feedback']['informative']
    # direct ARX is biased by the feedback (its residuals say so); IV on r is ok
    assert [m['status'] for m in result['models']][1] == 'ok' and code == result['exit_status']
    assert result['data']['inputs'] == ['ux']  # the instrument is not an input
    scale = np.array([1, 1, 1e-3, 1e-3])  # b in T/A
    direct, external = (np.array(m['theta']) / scale for m in result['models'])
    error = [np.linalg.norm(t - THETA_CL) / np.linalg.norm(THETA_CL) for t in (direct, external)]
    assert error[0] > 0.25 and error[1] < 0.03, error
