import numpy as np
import pytest

from maglev_ros.sysid import IdData, OrderError, arxstruc, delayest, selstruc

from .systems import simulate_mimo_arx, simulate_siso


def test_arxstruc_selstruc_find_true_orders():
    est, val = simulate_siso(8000, 3).split(0.5)
    search = arxstruc(est, val, range(1, 5), range(1, 5), 1)
    assert search.orders.shape == (16, 3)
    assert selstruc(search, 'mdl') == (2, 2, 1)
    na, nb, nk = selstruc(search, 'val')
    assert na >= 2 and nb >= 2
    assert selstruc(search, 'aic')[0] >= 2
    with pytest.raises(ValueError, match='criterion must be one of'):
        selstruc(search, 'bic')


def test_delayest_finds_delay():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(4000)
    from scipy.signal import lfilter

    y = lfilter([0, 0, 0, 0, 1.0, 0.4], [1, -0.8], u) + 0.05 * rng.standard_normal(4000)
    assert delayest(IdData(y, u, 1.0), nk=range(0, 8)) == 4


def test_selection_errors():
    with pytest.raises(OrderError, match='arxstruc searches SISO'):
        arxstruc(simulate_mimo_arx(200, 0))
    with pytest.raises(OrderError, match='na range must be non-empty'):
        arxstruc(simulate_siso(200, 0), na=[])
