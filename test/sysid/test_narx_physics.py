"""NARX against ARX on the simulated magnet's closed loop with large excitation.

Set-up: the closed loop (:mod:`physics_runs`) with a +-1.5 A PRBS on all four
coils (held 20 samples, 4 ms), well beyond the LQR's own 1 A, so the
magnet moves about 0.5 mm vertically and the loop saturates.  Model: the
excitation ``r`` (A) to the magnet's height ``z - z_eq`` (µm), decimated to
500 Hz; estimation and validation are two records with different PRBS and
noise seeds.
"""

import numpy as np

from maglev_ros.sysid import IdData, arx, compare
from maglev_ros.sysid.narx import narx

from .physics_runs import record

AMPLITUDE, CLOCK, SAMPLES, DECIMATE = 1.5, 0.05, 20000, 10
LAGS = (3, 3, 1)


def height_data(seed):
    result, r = record('z', AMPLITUDE, CLOCK, SAMPLES, seed)
    z = result.position_error()[:, 2] * 1e6
    data = IdData(z, r[:, 0], result.dt, ['z'], ['r_z'], ['µm'], ['A'])
    return data.decimate(DECIMATE)


def test_narx_beats_arx_of_the_same_lags_on_validation(capsys):
    est, val = height_data(1), height_data(2)
    na, nb, nk = LAGS
    linear = compare(arx(est, na, nb, nk), val, ic='estimate').fit[0]
    model = narx(est, na, nb, nk, degree=3, max_terms=40)
    nonlinear = compare(model, val, ic='estimate').fit[0]
    with capsys.disabled():
        print(f'\nvalidation simulation fit: ARX {na} {nb} {nk} {linear:.2f} %, '
              f'NARX degree 3 {nonlinear:.2f} % ({model.n_params} terms)')  # fmt: skip
        print(model)
    assert nonlinear > linear + 8.0  # measured: 82.80 % against 70.50 %
    names = model.term_names(0)
    assert any(name.count('*') or '^' in name for name in names)  # nonlinear terms chosen
    assert np.isfinite(model.simulate(val)).all()
