"""Is the dynamic calibration's reported uncertainty honest? Ten seeds of a nominal plant.

The plant is the nominal Maggy V2 (as in the main job, ``maglev-lab``): the
nominal KF + LQR hold it in the ROS-free closed loop
(:func:`maglev_ros.control.closed_loop.make_closed_loop`: sensor noise 0.1 mT,
0.098 mT quantisation, one sample of sensor delay, coil electrics) with a
random binary excitation (0.05 A per coil). For each seed, 2 s at 5 kHz are
recorded and ``magnet.mass`` and ``magnet.polarization`` are calibrated
(linear grey-box, first half estimation). The truth is the nominal value, so
``|estimate - truth| / std`` should be below 3 in nearly every run (about
99.7 % for an honest Gaussian standard deviation).

Printed per seed and parameter: the error in units of the reported (sandwich,
Newey-West) standard deviation and of the white-noise one ``s^2 (J^T J)^-1``
(what the calibration reported before), and their ratio.

Usage::

    python benchmarks/calibration_uncertainty.py            # 10 seeds, several minutes
    python benchmarks/calibration_uncertainty.py --seeds 3 --duration 1.5
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.excitation.signals import random_binary
from maglev_ros.greybox import LevitationExperiment, calibrate_dynamic, parameter_vector
from maglev_ros.physics import load_parameters

TS = 2e-4
FREE = ('magnet.mass', 'magnet.polarization')


def record(seed: int, duration: float) -> LevitationExperiment:
    """One closed-loop levitation record of the nominal plant."""
    base = load_parameters('maggy_v2')
    n = int(round(duration / TS))
    excitation = np.column_stack(
        [random_binary(n, 0.05, (0.0, 0.2), seed=10 * seed + j) for j in range(4)]
    )
    loop = make_closed_loop(base, plant=base, seed=seed)
    result = loop.run(duration, excitation=excitation)
    if result.crashed:
        raise RuntimeError(f'seed {seed}: {result.reason}')
    return LevitationExperiment(result.currents, result.readings, f'seed {seed}', TS)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, default=10)
    parser.add_argument('--duration', type=float, default=2.0)
    args = parser.parse_args()
    vector = parameter_vector(load_parameters('maggy_v2')).with_free(FREE)
    truth = {name: vector[name].nominal for name in FREE}
    rows = []
    head = f'{"seed":>4} {"parameter":<20} {"err/std":>8} {"err/std white":>14}'
    print(f'{head} {"ratio":>6} {"lags":>5}')
    for seed in range(args.seeds):
        start = time.perf_counter()
        cal = calibrate_dynamic(vector, [record(seed, args.duration)])
        for name in FREE:
            err = cal.estimate[name] - truth[name]
            z, zw = err / cal.std[name], err / cal.std_white[name]
            rows.append((abs(z), abs(zw)))
            print(
                f'{seed:>4} {name:<20} {z:>8.2f} {zw:>14.2f} '
                f'{cal.std[name] / cal.std_white[name]:>6.2f} {cal.hac_lags:>5}'
                + (f'   ({time.perf_counter() - start:.0f} s)' if name == FREE[-1] else '')
            )
    z = np.array(rows)
    print(
        f'within 3 std: reported (sandwich) {np.mean(z[:, 0] <= 3):.0%}, '
        f'white-noise formula {np.mean(z[:, 1] <= 3):.0%}; largest |err|/std: '
        f'{z[:, 0].max():.2f} reported, {z[:, 1].max():.2f} white'
    )


if __name__ == '__main__':
    main()
