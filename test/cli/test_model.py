"""maglev-model: subcommands, machine-readable output, one-line errors with status 2."""

import json

import numpy as np
import pytest

from maglev_ros.cli.model import main


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_equilibria_json(capsys):
    out = _json(capsys, ['equilibria', '--params', 'maggy_v4', '--json'])
    assert out['params'] == 'maggy_v4'
    assert out['equilibria'][0]['z'] == pytest.approx(0.030119178665731, abs=1e-12)
    assert out['equilibria'][0]['dFz_dz'] < 0
    assert out['inverted']
    assert out['correction'] == pytest.approx(0.5643948, rel=1e-6)


def test_linearize_json_has_matrices_in_the_stated_order(capsys):
    out = _json(capsys, ['linearize', '--json', '--reduced'])
    assert out['states'] == ['x', 'y', 'z', 'alpha', 'beta', 'vx', 'vy', 'vz', 'wx', 'wy']
    assert out['inputs'] == ['x+', 'x-', 'y+', 'y-']
    assert len(out['outputs']) == 9
    assert np.array(out['A']).shape == (10, 10) and np.array(out['B']).shape == (10, 4)
    assert np.array(out['C']).shape == (9, 10) and np.array(out['D']).shape == (9, 4)
    assert out['ranks'] == {'controllability': 10, 'observability': 10, 'states': 10}
    assert out['z_eq'] == pytest.approx(0.0365, abs=1e-4)


def test_linearize_text_shows_published_torque_stiffness(capsys):
    assert main(['linearize', '--torque', 'published']) == 0
    text = capsys.readouterr().out
    assert 'z_eq = 0.0365' in text and 'solenoid radius factor 0.5583' in text
    assert '768.' in text  # the published tilt frequency, rad/s


def test_simulate_writes_plot_and_csv(capsys, tmp_path):
    png, csv = tmp_path / 'sim.png', tmp_path / 'sim.csv'
    out = _json(
        capsys, ['simulate', '--duration', '0.05', '--json', '--plot', str(png), '--csv', str(csv)]
    )
    assert out['status'] == 'ok' and out['samples'] == 250
    assert png.read_bytes()[:4] == b'\x89PNG'
    table = np.loadtxt(csv, delimiter=',', skiprows=1)
    assert table.shape == (251, 1 + 12 + 9)


def test_simulate_reports_a_crash(capsys):
    out = _json(capsys, ['simulate', '--duration', '1', '--perturb', 'x=0.001', '--json'])
    assert out['status'] == 'crashed' and 0 < out['crash_time'] < 1
    assert out['reason'] in ('touched the base', 'left the workspace')
    assert all(np.isfinite(out['crash_state']))


@pytest.mark.parametrize(
    'argv, message',
    [
        (['equilibria', '--params', 'missing.yaml'], 'missing.yaml: parameter file not found'),
        (['simulate', '--perturb', 'q=1'], 'expected NAME=VALUE'),
        (['simulate', '--duration', '-1'], 'must be positive'),
        (['simulate', '--currents', '1', '2'], 'expected 4 values'),
        (['linearize', '--model', 'exact'], "invalid choice: 'exact'"),
        (['equilibria', '--correction', 'big'], '--correction: expected auto, none or a number'),
        ([], 'required: command'),
    ],
)
def test_bad_input_exits_2_with_one_line(capsys, argv, message):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ''
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('maglev-model: error: ')
    assert message in lines[0]


def test_simulation_figure_shows_the_simulated_signals():
    import matplotlib.pyplot as plt

    from maglev_ros.cli.model import simulation_figure
    from maglev_ros.physics import Simulator, make_model, rest_state

    model = make_model('maggy_v2')
    x0 = rest_state(model)
    x0[0] += 0.001  # off centre: the magnet moves, then crashes
    result = Simulator(model, sample_rate=5000.0).run(np.zeros((100, 4)), x0=x0)
    fig = simulation_figure(result, 'maggy_v2')
    try:
        position, angles, field = fig.axes
        assert [ax.get_ylabel() for ax in fig.axes] == ['position, mm', 'angle, rad', 'field, mT']
        assert field.get_xlabel() == 'time, s'
        assert fig._suptitle.get_text().startswith('maggy_v2: simulation (')
        assert [line.get_label() for line in position.lines] == ['x', 'y', 'z']
        np.testing.assert_array_equal(position.lines[0].get_xdata(), result.t)
        np.testing.assert_allclose(position.lines[2].get_ydata(), result.x[:, 2] * 1e3)
        assert [line.get_label() for line in angles.lines] == ['alpha', 'beta', 'gamma']
        n_sensors = result.y.shape[1] // 3
        assert [line.get_label() for line in field.lines] == [f'Bz_{k}' for k in range(n_sensors)]
        np.testing.assert_allclose(field.lines[1].get_ydata(), result.y[:, 5] * 1e3)
        assert np.ptp(position.lines[0].get_ydata()) > 0  # the x motion is drawn
    finally:
        plt.close(fig)
