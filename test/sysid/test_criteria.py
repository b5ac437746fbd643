import numpy as np
import pytest

from maglev_ros.sysid import aic, fit_percent, fpe, mdl


def test_fit_is_the_toolbox_formula():
    y = np.array([1.0, 2.0, 3.0])
    yhat = np.array([1.0, 2.0, 4.0])
    assert fit_percent(y, yhat)[0] == pytest.approx(100 * (1 - 1 / np.sqrt(2)), abs=1e-12)
    rng = np.random.default_rng(0)
    Y = rng.standard_normal((200, 2))
    Yh = Y + 0.3 * rng.standard_normal((200, 2))
    for i in range(2):
        expected = 100 * (
            1 - np.linalg.norm(Y[:, i] - Yh[:, i]) / np.linalg.norm(Y[:, i] - Y[:, i].mean())
        )
        assert fit_percent(Y, Yh)[i] == pytest.approx(expected, rel=1e-14)
    assert fit_percent(Y, Y)[0] == 100.0
    assert fit_percent(Y[:, 0], np.full(200, Y[:, 0].mean()))[0] == pytest.approx(0.0, abs=1e-12)


def test_fit_shape_mismatch():
    with pytest.raises(ValueError, match='y has shape'):
        fit_percent(np.zeros(3), np.zeros(4))


def test_fpe_aic_mdl_definitions():
    rng = np.random.default_rng(1)
    e = rng.standard_normal((1000, 1))
    V = float(e[:, 0] @ e[:, 0]) / 1000
    assert fpe(e, 10) == pytest.approx(V * (1 + 0.01) / (1 - 0.01))
    assert aic(e, 10) == pytest.approx(1000 * np.log(V) + 20 + 1000 * (np.log(2 * np.pi) + 1))
    assert mdl(e, 10) == pytest.approx(V * (1 + 10 * np.log(1000) / 1000))
    assert fpe(e, 1000) == float('inf')


def test_a_diverging_output_fits_minus_infinity_without_a_warning():
    """An unstable model's simulation grows past float range: its fit is -inf, quietly."""
    import warnings

    y = np.sin(np.arange(100.0))
    yhat = 1e200 * 1.5 ** np.arange(100.0)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert fit_percent(y, yhat).tolist() == [-np.inf]
