"""End to end: maglev-lab records a perturbed plant (simulator node, recorder), maglev-calibrate
recovers it from the bags."""

from __future__ import annotations

from functools import cache

import yaml

from maglev_ros.cli import calibrate, lab
from maglev_ros.greybox import parameter_vector, write_parameters
from maglev_ros.physics import load_parameters


@cache
def nominal_vector():
    return parameter_vector(load_parameters('maggy_v2'))


@cache
def truth() -> dict[str, float]:
    """The plant: several parameters off nominal at once."""
    v = nominal_vector()
    return {
        'coil0.gain': 1.03,
        'coil1.gain': 0.97,
        'coil2.gain': 1.02,
        'coil3.gain': 0.985,
        'sensor1.x': v['sensor1.x'].nominal + 3e-4,
        'sensor2.y': v['sensor2.y'].nominal - 2e-4,
        'sensor1.gain_z': 1.02,
        'magnet.polarization': -0.98,
        'magnet.mass': 0.08,
    }


def _record(tmp_path, plant, magnet):
    out = tmp_path / magnet
    argv = [
        '--params', str(plant), '--magnet', magnet, '--sensors', '0', '1', '2',
        '--pattern', 'independent', '--excitation', 'prbs', '--amplitude', '0.8',
        '--band', '0', '0.05',
        '--noise', '1e-4', '--duration', '2.0', '--seed', '5' if magnet == 'fixed' else '4',
        '--no-plots', '--out', str(out),
    ]  # fmt: skip
    # the session's own ARX 2 2 1 does not describe this plant: its residual tests fail
    # (exit 1, the rows say so); the bag is what this test needs
    assert lab.main(argv) in (0, 1)
    return out / 'bag'


def test_lab_bags_of_a_perturbed_plant_calibrate_back(domain, tmp_path, capfd):
    plant = write_parameters(nominal_vector().apply(truth()), tmp_path / 'plant.yaml')
    bags = [_record(tmp_path, plant, m) for m in ('absent', 'fixed')]
    capfd.readouterr()
    out = tmp_path / 'board.yaml'
    free = ['coil*.gain', 'sensor1.x', 'sensor2.y', 'sensor1.gain_z', 'magnet.polarization']
    status = calibrate.main([*map(str, bags), '--free', *free, '--out', str(out)])
    captured = capfd.readouterr()
    assert status == 0, captured.err
    assert 'sensors 0, 1, 2' in captured.out and 'magnet fixed' in captured.out
    header = [line for line in out.read_text().splitlines() if line.startswith('#   ')]
    estimates = {}
    for line in header:  # '#   coil0.gain = 1.03 +- 0.001 (nominal 1)'
        name, _, rest = line[4:].partition(' = ')
        value, _, rest = rest.partition(' +- ')
        estimates[name] = (float(value.split()[0]), float(rest.split()[0]))
    scale = {'sensor1.x': 1e-3, 'sensor2.y': 1e-3}  # written in mm
    for name in ('coil0.gain', 'coil1.gain', 'coil2.gain', 'coil3.gain', 'sensor1.gain_z'):
        est, sd = estimates[name]
        assert abs(est - truth()[name]) <= max(3 * sd, 1e-12), (name, est, sd)
        assert abs(est - truth()[name]) <= 0.01 * truth()[name], captured.out
    for name in ('sensor1.x', 'sensor2.y'):
        est, sd = (v * scale[name] for v in estimates[name])
        assert abs(est - truth()[name]) <= 3 * sd, (name, est, sd)
        assert abs(est - truth()[name]) <= 50e-6
    est, sd = estimates['magnet.polarization']
    assert abs(est - truth()['magnet.polarization']) <= 3 * sd
    calibrated = yaml.safe_load(out.read_text())
    assert calibrated['solenoid_radius_correction'] > 0
