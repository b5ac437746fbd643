"""Force and torque on the levitating magnet; equilibria; the solenoid correction."""

import numpy as np
import pytest

from maglev_ros.physics.equilibria import find_equilibria
from maglev_ros.physics.kernels import GRAVITY
from maglev_ros.physics.model import DEFAULT_RIM_POINTS, make_model, solenoid_radius_correction
from maglev_ros.physics.parameters import load_parameters


def _states(model, z_eq, seed=0, count=6):
    rng = np.random.default_rng(seed)
    states = [model.hover_state(z_eq)]
    for _ in range(count):
        x = model.hover_state(z_eq)
        x[:3] += rng.normal(size=3) * 0.002
        x[3:6] += rng.normal(size=3) * 0.05
        states.append(x)
    return states


def test_rim_sum_has_converged_at_the_default_n(fast_model):
    z_eq = find_equilibria(fast_model)[0].z
    fine = fast_model.with_options(rim_points=400)
    u = np.array([0.4, -0.3, 0.2, 0.1])
    for x in _states(fast_model, z_eq):
        f = fast_model.wrench(x, u)[:3]
        f_fine = fine.wrench(x, u)[:3]
        assert np.linalg.norm(f - f_fine) / np.linalg.norm(f_fine) < 1e-8
    assert DEFAULT_RIM_POINTS == fast_model.rim_points


def test_centred_equilibrium_is_symmetric_and_carries_the_weight(fast_model):
    eq = find_equilibria(fast_model)[0]
    force, torque = fast_model.force_and_torque(fast_model.hover_state(eq.z))
    weight = fast_model.params.magnet.mass * GRAVITY
    assert force[2] == pytest.approx(weight, rel=1e-12)
    assert np.all(np.abs(force[:2]) <= 1e-15 * weight)
    assert np.all(np.abs(torque) <= 1e-15 * weight * fast_model.params.magnet.radius)


def test_published_equilibria_and_stiffness():
    # Engmark & Hoang's sets: V2 about 36.50 mm, V4 30.119178665731 mm (published code)
    v2 = find_equilibria(make_model('maggy_v2'))
    v4 = find_equilibria(make_model('maggy_v4'))
    assert len(v2) == 1 and v2[0].z == pytest.approx(0.03650, abs=1e-5)
    assert v4[0].z == pytest.approx(0.030119178665731, abs=1e-12)
    assert v2[0].stiffness < 0 and v4[0].stiffness < 0


def test_inverted_equilibria_are_reported():
    inverted = find_equilibria(make_model('maggy_v4'), inverted=True)
    assert inverted and all(e.inverted for e in inverted)
    assert any(e.stiffness > 0 for e in inverted)


@pytest.mark.parametrize(
    'name, published', [('maggy_v2', 0.558361865282244), ('maggy_v4', 0.564394804131228)]
)
def test_solenoid_radius_correction_reproduces_the_published_factor(name, published):
    # the published values come from fmincon (tolerance ~1e-8 on c); ours is a root
    assert solenoid_radius_correction(load_parameters(name)) == pytest.approx(published, rel=1e-7)


def test_correction_override_and_none():
    params = load_parameters('maggy_v2')
    assert make_model(params.replace(solenoid_radius_correction=0.6)).correction == 0.6
    assert make_model(params, correction='none').correction == 1.0
    assert make_model(params, correction=0.7).correction == 0.7
    assert make_model(params, field='accurate').correction == 1.0


def test_forces_do_not_depend_on_the_torque_choice(v2, v2_equilibrium):
    published = v2.with_options(torque='published')
    x = v2_equilibrium.copy()
    x[3] = 0.05
    u = np.array([0.5, 0.1, -0.2, 0.3])
    np.testing.assert_array_equal(v2.wrench(x, u)[:3], published.wrench(x, u)[:3])
    true_tau = v2.wrench(x, u)[3]
    published_tau = published.wrench(x, u)[3]
    assert abs(published_tau) > 10 * abs(true_tau)  # tens of times too stiff


def test_true_torque_is_the_virtual_work_derivative(v2, v2_equilibrium):
    # A current loop in an external field has the interaction energy U = -I flux; the
    # torque about an axis is -dU/dangle = I dflux/dangle with I = K0 l (the rim current).
    x = v2_equilibrium.copy()
    x[0] = 0.002
    x[3] = 0.03
    h = 1e-5
    linkage = []
    for da in (-h, h):
        xs = x.copy()
        xs[3] += da
        linkage.append(_linkage(v2, xs))
    derivative = (linkage[1] - linkage[0]) / (2 * h)
    # varying alpha rotates about the intermediate x axis Rz(gamma) Ry(beta) e_x
    axis = np.array([np.cos(x[5]) * np.cos(x[4]), np.sin(x[5]) * np.cos(x[4]), -np.sin(x[4])])
    torque = v2.wrench(x)[3:]
    assert np.dot(torque, axis) == pytest.approx(derivative, rel=1e-4)
    published = v2.with_options(torque='published').wrench(x)[3:]
    assert abs(np.dot(published, axis) - derivative) > 10 * abs(derivative)


def _linkage(model, x):
    """Flux linkage of the rim current with the base field, K0 l * flux (J)."""
    from maglev_ros.physics.kernels import rotation_matrix

    m = model.params.magnet
    r = rotation_matrix(x[3], x[4], x[5])
    n_r, n_t = 200, 64
    radii = (np.arange(n_r) + 0.5) / n_r * m.radius
    theta = 2 * np.pi * np.arange(n_t) / n_t
    rr, tt = np.meshgrid(radii, theta, indexing='ij')
    local = np.column_stack(
        [(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel(), np.zeros(rr.size)]
    )
    field = model.field_at(x[:3] + local @ r.T)
    normal = r[:, 2]
    flux = np.sum(field @ normal * (rr.ravel() * (m.radius / n_r) * (2 * np.pi / n_t)))
    return model.k0 * m.thickness * flux


def test_accurate_model_is_close_to_fast_and_symmetric():
    fast = make_model('maggy_v2')
    accurate = make_model('maggy_v2', field='accurate')
    z = find_equilibria(fast)[0].z
    f_fast = fast.wrench(fast.hover_state(z))
    f_acc = accurate.wrench(accurate.hover_state(z))
    assert np.all(np.isfinite(f_acc))
    assert abs(f_acc[2] - f_fast[2]) < 0.2 * f_fast[2]
    assert np.all(np.abs(f_acc[[0, 1, 3, 4, 5]]) < 1e-9 * f_acc[2])
