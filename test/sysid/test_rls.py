import numpy as np
import pytest

from maglev_ros.sysid import RecursiveArx, arx, rls_arx

from .systems import mimo_arx_truth, simulate_mimo_arx, simulate_siso


def test_rls_without_forgetting_converges_to_batch_arx():
    data = simulate_siso(8000, 3)
    batch = arx(data, 2, 2, 1)
    result = rls_arx(data, 2, 2, 1, forgetting=1.0, p0=1e8)
    assert np.allclose(result.theta[-1], batch.theta, atol=2e-4)
    early = np.linalg.norm(result.theta[200] - batch.theta)
    assert np.linalg.norm(result.theta[-1] - batch.theta) < 0.05 * early


def test_rls_mimo_converges_to_batch_arx():
    na, nb, nk = [[4, 4], [0, 4]], [[2, 2], [0, 2]], [[1, 1], [1, 1]]
    data = simulate_mimo_arx(6000, 2)
    result = rls_arx(data, na, nb, nk, p0=1e8)
    assert np.allclose(result.theta[-1], arx(data, na, nb, nk).theta, atol=1e-3)
    assert np.max(np.abs(result.theta[-1] - mimo_arx_truth())) < 0.05


def test_online_estimator_matches_batch_kernel():
    data = simulate_siso(400, 1)
    online = RecursiveArx(2, 2, 1, forgetting=0.98, p0=100.0)
    for y, u in zip(data.y, data.u, strict=True):
        theta = online.update(y, u)
    batch = rls_arx(data, 2, 2, 1, forgetting=0.98, p0=100.0)
    assert np.allclose(theta, batch.theta[-1], rtol=1e-9, atol=1e-12)
    assert online.n_updates == 400
    assert np.allclose(online.model(data.Ts).theta, theta)


def test_forgetting_tracks_a_parameter_change():
    first = simulate_siso(3000, 1)
    second = simulate_siso(3000, 2, A=np.array([1.0, -1.2, 0.5]))
    from maglev_ros.sysid import IdData

    data = IdData(np.vstack([first.y, second.y]), np.vstack([first.u, second.u]), first.Ts)
    tracked = rls_arx(data, 2, 2, 1, forgetting=0.99).theta[-1]
    frozen = rls_arx(data, 2, 2, 1, forgetting=1.0).theta[-1]
    assert abs(tracked[0] - (-1.2)) < 0.02
    assert abs(frozen[0] - (-1.2)) > 0.05


def test_rls_argument_errors():
    with pytest.raises(ValueError, match='forgetting factor must be in'):
        RecursiveArx(2, 2, forgetting=1.5)
    with pytest.raises(ValueError, match='p0'):
        rls_arx(simulate_siso(100, 0), 1, 1, p0=0)
    est = RecursiveArx(1, 1)
    with pytest.raises(ValueError, match='update needs y of shape'):
        est.update([1.0, 2.0], [0.0])
