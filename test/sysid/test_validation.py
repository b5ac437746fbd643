import numpy as np
import pytest

from maglev_ros.sysid import IdData, armax, arx, compare, fit_percent, resid

from .systems import C_ARMAX, simulate_siso


def test_compare_uses_toolbox_fit_for_simulation_and_prediction():
    est, val = simulate_siso(8000, 1).split(0.5)
    model = arx(est, 2, 2, 1)
    sim = compare(model, val)
    assert sim.horizon is None
    assert np.allclose(sim.fit, fit_percent(val.y, model.simulate(val)))
    pred = compare(model, val, horizon=1)
    assert np.allclose(pred.yhat, val.y - model.residuals(val))
    assert pred.fit[0] > sim.fit[0]
    fits = [compare(model, val, horizon=k).fit[0] for k in (1, 3, 10, 200)]
    assert fits == sorted(fits, reverse=True)
    assert fits[-1] == pytest.approx(sim.fit[0], abs=0.5)


def test_one_step_prediction_of_arx_is_the_regression():
    data = simulate_siso(500, 2)
    model = arx(data, 2, 2, 1)
    a1, a2, b1, b2 = model.theta
    y, u = data.y[:, 0], data.u[:, 0]
    direct = -a1 * y[1:-1] - a2 * y[:-2] + b1 * u[1:-1] + b2 * u[:-2]
    assert np.allclose(model.predict(data)[2:, 0], direct)


def test_k_step_prediction_matches_explicit_recursion():
    data = simulate_siso(300, 3)
    model = arx(data, 2, 2, 1)
    a1, a2, b1, b2 = model.theta
    y, u = data.y[:, 0], data.u[:, 0]
    k = 3
    yhat = model.predict(data, k=k)[:, 0]
    for t in range(10, 300):
        known = list(y[: t - k + 1])  # y up to t-k
        for s in range(t - k + 1, t + 1):
            known.append(-a1 * known[s - 1] - a2 * known[s - 2] + b1 * u[s - 1] + b2 * u[s - 2])
        assert yhat[t] == pytest.approx(known[t], abs=1e-10)


def test_estimated_initial_conditions_remove_transient():
    data = simulate_siso(3000, 4, noise=0.0)
    tail = data[1000:]  # starts with a non-zero state
    model = arx(data, 2, 2, 1)
    zero = compare(model, tail).fit[0]
    est = compare(model, tail, ic='estimate').fit[0]
    assert est > 99.99 > zero
    with pytest.raises(ValueError, match="ic must be 'zero' or 'estimate'"):
        compare(model, tail, ic='guess')


def test_residual_test_passes_true_structure_and_fails_too_low_order():
    data = simulate_siso(10000, 6, C=C_ARMAX, noise=0.5)
    est, val = data.split(0.5)
    good = resid(armax(est, 2, 2, 1, 1), val)
    assert good.passed, good.summary()
    assert np.all(np.abs(good.autocorr[:, 1:]) < 2 * good.bound)
    low = resid(arx(est, 1, 1, 1), val)
    assert not low.white and not low.passed
    assert 'FAIL' in low.summary()
    assert good.autocorr[0, 0] == pytest.approx(1.0)


def test_residual_independence_detects_missing_input():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((6000, 2))
    y = (
        np.convolve(u[:, 0], [0, 1.0])[:6000]
        + np.convolve(u[:, 1], [0, 0, 0.5])[:6000]
        + 0.1 * rng.standard_normal(6000)
    )
    data = IdData(y, u, 1e-3)
    model = arx(data.select(inputs=[0]), 0, 1, 1)
    analysis = resid(model, data.select(inputs=[0]))
    assert analysis.independent  # u1 itself is modelled; u2 acts as white noise
    full = arx(data, 0, [1, 1], [1, 2])
    assert resid(full, data).passed
    partial = arx(data, 0, [1, 1], [1, 1])  # misses the 2-sample delay of u2
    assert not resid(partial, data).independent


def test_resid_argument_errors():
    data = simulate_siso(100, 0)
    model = arx(data, 1, 1, 1)
    with pytest.raises(ValueError, match='max_lag must be >= 1'):
        resid(model, data, max_lag=0)
    with pytest.raises(ValueError, match='too large'):
        resid(model, data, max_lag=60)


def test_diverging_simulation_is_refused_before_lapack(capfd):
    # pole 1.5: the simulation overflows after ~1800 samples; lstsq on inf would print
    # "On entry to DLASCL parameter number 4" on fd 1 and raise "SVD did not converge"
    from maglev_ros.sysid import DivergenceError, PolyModel
    from maglev_ros.sysid.orders import make_orders

    rng = np.random.default_rng(0)
    u = rng.standard_normal((3000, 1))
    data = IdData(rng.standard_normal((3000, 1)), u, 1.0)
    model = PolyModel(
        'arx', make_orders(1, 1, na=1, nb=1, nk=1), np.array([-1.5, 1.0]), 1.0, np.eye(1)
    )
    with pytest.raises(DivergenceError, match='largest pole magnitude 1.5'):
        compare(model, data, ic='estimate')
    out, err = capfd.readouterr()
    assert out == '' and err == ''
