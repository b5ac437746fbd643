import control
import numpy as np
import pytest

from maglev_ros.sysid import PolyModel, arx, bj, make_orders

from .systems import A2, B2, C_BJ, D_BJ, F_OE, simulate_mimo_arx, simulate_siso


def arx_model():
    orders = make_orders(1, 1, na=2, nb=2, nk=1)
    return PolyModel('arx', orders, np.concatenate([A2[1:], B2[1:]]), 0.01, np.eye(1))


def test_simulate_matches_lfilter():
    from scipy.signal import lfilter

    u = np.random.default_rng(0).standard_normal(300)
    assert np.allclose(arx_model().simulate(u)[:, 0], lfilter(B2, A2, u))


def test_poles_zeros_stability():
    model = arx_model()
    assert np.allclose(np.sort_complex(model.poles()), np.sort_complex(np.roots(A2)))
    assert np.allclose(model.zeros(), [-0.5])
    assert model.is_stable
    unstable = PolyModel('arx', model.orders, [-2.5, 1.2, 1.0, 0.0], 0.01, np.eye(1))
    assert not unstable.is_stable


def test_freqresp_matches_python_control():
    model = arx_model()
    f = np.array([0.5, 5.0, 20.0])
    H = model.freqresp(f)[:, 0, 0]
    tf = model.to_tf()
    assert isinstance(tf, control.TransferFunction) and tf.dt == 0.01
    ref = tf(np.exp(2j * np.pi * f * 0.01))
    assert np.allclose(H, np.squeeze(ref))
    ss = model.to_ss()
    assert np.allclose(np.squeeze(ss(np.exp(2j * np.pi * f * 0.01))), H)


def test_mimo_coupled_transfer_function_and_poles():
    model = arx(simulate_mimo_arx(4000, 1), [[4, 4], [0, 4]], [[2, 2], [0, 2]], 1)
    f = np.array([1.0, 100.0, 1000.0])
    z = np.exp(2j * np.pi * f * model.Ts)
    H = model.freqresp(f)
    tf_vals = model.to_tf()(z)
    ss_vals = model.to_ss()(z)
    for k in range(3):
        assert np.allclose(tf_vals[:, :, k], H[k], rtol=1e-6, atol=1e-9)
        assert np.allclose(ss_vals[:, :, k], H[k], rtol=1e-6, atol=1e-9)
    assert model.is_stable
    roots = np.concatenate(
        [np.roots(model.polynomial('A', 0, 0)), np.roots(model.polynomial('A', 1, 1))]
    )
    assert np.allclose(np.sort_complex(model.poles()), np.sort_complex(roots), atol=1e-6)


def test_bj_to_tf_uses_f_and_noise_model_in_ss():
    model = bj(simulate_siso(5000, 1, A=np.ones(1), F=F_OE, C=C_BJ, D=D_BJ), 2, 1, 1, 2, 1)
    f = np.array([3.0, 300.0])
    z = np.exp(2j * np.pi * f * model.Ts)
    assert np.allclose(np.squeeze(model.to_tf()(z)), model.freqresp(f)[:, 0, 0])
    noisy = model.to_ss(noise=True)
    assert noisy.ninputs == 2
    assert np.allclose(np.sort_complex(model.poles()), np.sort_complex(np.roots(model.F[0, 0])))


def test_text_form():
    model = arx(simulate_siso(3000, 1), 2, 2, 1)
    text = str(model)
    assert 'Discrete-time ARX model:  A(z)y(t) = B(z)u(t) + e(t)' in text
    assert 'A(z) = 1 - 1.49' in text and 'z^-2' in text
    assert 'Orders: na=2  nb=2  nk=1' in text
    assert 'Fit to estimation data:' in text and 'FPE:' in text and 'MSE:' in text
    assert 'Sample time: 0.0002 seconds' in text
    assert 'std:' in text


def test_model_argument_errors():
    orders = make_orders(1, 1, na=1, nb=1)
    with pytest.raises(ValueError, match='structure must be one of'):
        PolyModel('nlarx', orders, [0.1, 1.0], 0.1, np.eye(1))
    with pytest.raises(ValueError, match='Ts must be > 0'):
        PolyModel('arx', orders, [0.1, 1.0], 0.0, np.eye(1))
    with pytest.raises(ValueError, match=r'theta must have shape \(2,\)'):
        PolyModel('arx', orders, [0.1], 0.1, np.eye(1))
    model = PolyModel('arx', orders, [0.1, 1.0], 0.1, np.eye(1))
    with pytest.raises(ValueError, match=r'input must have shape \(N, 1\)'):
        model.simulate(np.zeros((10, 2)))
    with pytest.raises(ValueError, match='prediction horizon k must be >= 1'):
        model.predict(simulate_siso(20, 0), k=0)


def test_filter_residuals_equal_kalman_predictor_and_simulation_paths_agree():
    mimo = arx(simulate_mimo_arx(2000, 1), [[4, 4], [0, 4]], [[2, 2], [0, 2]], 1)
    data = simulate_mimo_arx(500, 2)
    assert np.allclose(mimo.residuals(data), mimo.residuals_state_space(data), atol=1e-10)
    siso = bj(simulate_siso(3000, 1, A=np.ones(1), F=F_OE, C=C_BJ, D=D_BJ), 2, 1, 1, 2, 1)
    d = simulate_siso(400, 3)
    assert np.allclose(siso.residuals(d), siso.residuals_state_space(d), atol=1e-10)
    from maglev_ros.sysid.polynomial import innovations_form, simulate_ss

    A, B, C, D, _ = innovations_form(siso._polys, noise=False)
    ss = simulate_ss(A, B, C, D, np.zeros(A.shape[0]), np.ascontiguousarray(d.u))
    assert np.allclose(siso.simulate(d), ss, atol=1e-10)
