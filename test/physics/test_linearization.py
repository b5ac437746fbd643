"""Linearisation about the equilibrium: instability, ranks, tilt stiffness, smooth Jacobians."""

import numpy as np
import pytest

from maglev_ros.physics.linearization import (
    controllability_rank,
    linearize,
    observability_rank,
)
from maglev_ros.physics.model import make_model


@pytest.fixture(scope='module', params=['maggy_v2', 'maggy_v4'])
def linear(request):
    return linearize(make_model(request.param))


def test_open_loop_is_unstable_and_vertically_stable(linear):
    assert not linear.is_stable
    assert np.max(linear.poles.real) > 1.0
    i_vz, i_z = linear.states.index('vz'), linear.states.index('z')
    assert linear.A[i_vz, i_z] < 0  # dFz/dz < 0: the permanent magnets hold z


def test_reduced_model_is_controllable_and_observable_with_the_v2_sensors(linear):
    reduced = linear.reduced()
    assert reduced.states == ('x', 'y', 'z', 'alpha', 'beta', 'vx', 'vy', 'vz', 'wx', 'wy')
    assert reduced.A.shape == (10, 10) and reduced.B.shape == (10, 4)
    assert reduced.C.shape == (9, 10)
    assert reduced.controllability_rank() == 10
    assert reduced.observability_rank() == 10
    # the raw matrices span many decades; a rank test on them would be meaningless
    assert np.ptp(np.log10(np.abs(reduced.A[reduced.A != 0]))) > 5


def test_rank_tests_detect_missing_inputs_and_outputs(linear):
    reduced = linear.reduced()
    x_only = reduced.B[:, :2]  # the x pair alone cannot move y
    assert controllability_rank(reduced.A, x_only) < 10
    only_bz = reduced.C[2:3]  # one vertical field component cannot see x vs -x
    assert observability_rank(reduced.A, only_bz) < 10


def test_true_torque_gives_the_physical_tilt_frequency():
    v2 = make_model('maggy_v2')
    true_poles = linearize(v2).reduced().poles
    published_poles = linearize(v2.with_options(torque='published')).reduced().poles
    tilt_true = np.max(np.abs(true_poles.imag))
    tilt_published = np.max(np.abs(published_poles.imag))
    assert tilt_true == pytest.approx(90, rel=0.05)  # about 90 rad/s
    assert tilt_published == pytest.approx(769, rel=0.01)  # the published 769 rad/s
    # translation rows and B's translational rows do not depend on the torque choice
    lin_t, lin_p = linearize(v2), linearize(v2.with_options(torque='published'))
    np.testing.assert_allclose(lin_t.A[6:9], lin_p.A[6:9], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lin_t.B[6:9], lin_p.B[6:9], rtol=1e-12, atol=1e-12)


def test_on_axis_sensor_jacobian_does_not_depend_on_the_step():
    v2 = make_model('maggy_v2')
    assert np.allclose(v2.params.sensors[0].position, 0.0)  # the V2 sensor on the axis
    fine = linearize(v2, step=1e-6).C[:3]
    coarse = linearize(v2, step=1e-4).C[:3]
    scale = np.max(np.abs(fine), axis=1, keepdims=True)
    assert np.max(np.abs(fine - coarse) / scale) < 1e-3
    i_beta = 4
    assert fine[0, i_beta] != 0.0  # the tilt column is not lost near the axis


def test_published_kinematics_linearise_the_same_at_zero_angles():
    v2 = make_model('maggy_v2')
    np.testing.assert_allclose(
        linearize(v2).A, linearize(v2.with_options(kinematics='published')).A, rtol=1e-9, atol=1e-9
    )


def test_statespace_conversion_keeps_names(linear):
    ss = linear.reduced().to_statespace()
    assert ss.nstates == 10 and ss.ninputs == 4 and ss.noutputs == 9
    assert ss.input_labels == ['x+', 'x-', 'y+', 'y-']
