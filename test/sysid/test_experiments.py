"""Several experiments: k-fold and by-experiment tables, every estimator, parameter variance."""

import numpy as np
import pytest

from maglev_ros.sysid import armax, arx, iv4
from maglev_ros.sysid.experiments import by_experiment, kfold
from maglev_ros.sysid.narx import narx

from .physics_runs import lab_x
from .systems import C_ARMAX, simulate_siso


@pytest.fixture(scope='module')
def four():
    return [simulate_siso(1500, seed=s, C=C_ARMAX) for s in range(4)]


@pytest.mark.parametrize(
    'estimator',
    [
        lambda d: arx(d, 2, 2, 1),
        lambda d: iv4(d, 2, 2, 1),
        lambda d: armax(d, 2, 2, 1, 1),
        lambda d: narx(d, 2, 2, 1, degree=1),
    ],
    ids=['arx', 'iv', 'armax', 'narx'],
)
def test_leave_one_out_table_for_every_estimator(four, estimator):
    table = kfold(four, estimator, labels=['a.npz', 'b.npz', 'c.npz', 'd.npz'])
    assert [f.validation for f in table.folds] == [(0,), (1,), (2,), (3,)]
    assert [f.estimation for f in table.folds][0] == (1, 2, 3)
    assert table.fits.shape == (4, 1) and np.all(table.fits > 50)
    text = table.text()
    assert 'b.npz, c.npz, d.npz' in text and text.splitlines()[-1].startswith('mean')
    assert table.to_dict()['folds'][3]['validation'] == ['d.npz']


def test_two_folds_and_by_experiment(four):
    table = kfold(four, lambda d: arx(d, 2, 2, 1), k=2, horizon=3)
    assert [f.validation for f in table.folds] == [(0, 2), (1, 3)]
    assert '3-step prediction' in table.text()
    single = by_experiment(four, lambda d: arx(d, 2, 2, 1))
    assert [f.estimation for f in single.folds] == [(0,), (1,), (2,), (3,)]
    with pytest.raises(ValueError, match='needs 2 <= k <= 4'):
        kfold(four, lambda d: arx(d, 2, 2, 1), k=5)
    with pytest.raises(ValueError, match='at least two'):
        by_experiment(four[:1], lambda d: arx(d, 2, 2, 1))


def test_a_failing_fold_is_a_row(four):
    def estimator(d):
        if len(d) == 3 and d[0] is four[1]:
            raise ValueError('no luck')
        return arx(d, 2, 2, 1)

    table = kfold(four, estimator)
    assert table.folds[0].error == 'failed: no luck' and np.isnan(table.fits[0, 0])
    assert np.isfinite(table.mean[0])


def test_three_records_give_a_lower_parameter_variance_than_any_one(capsys):
    """The lab's ARX 7 9 1 on three closed-loop records of the simulated magnet."""
    records = [lab_x(seed, 12500) for seed in (0, 1, 2)]
    single = [arx(d, 7, 9, 1).std for d in records]
    joint = arx(records, 7, 9, 1).std
    table = kfold(records, lambda d: arx(d, 7, 9, 1), labels=['run0', 'run1', 'run2'])
    with capsys.disabled():
        ratios = joint / np.min(single, axis=0)
        print(f'\nstd(3 records) / min std(one record): {ratios.min():.2f} .. {ratios.max():.2f}')
        print(table.text())
    assert np.all(joint < np.min(single, axis=0))
    assert np.all(np.isfinite(table.fits))
