"""Field kernels against magpylib (an independent, well-kept library) and analytic limits."""

import magpylib as magpy
import numpy as np
import pytest

from maglev_ros.physics.filament import filament_loops
from maglev_ros.physics.loop import MU0, loop_field, loop_field_cylindrical
from maglev_ros.physics.sheet import sheet_field


def _points(rng, scale):
    near = rng.normal(size=(300, 3)) * scale
    on_axis = np.column_stack([np.zeros(20), np.zeros(20), np.linspace(-5, 5, 20) * scale])
    near_axis = np.column_stack(
        [np.geomspace(1e-12, 1e-3, 20) * scale, np.zeros(20), np.full(20, 0.7 * scale)]
    )
    far = rng.normal(size=(50, 3)) * 200 * scale
    return np.vstack([near, on_axis, near_axis, far])


def _relative_error(b, ref):
    return np.linalg.norm(b - ref, axis=1) / np.linalg.norm(ref, axis=1)


@pytest.mark.parametrize('radius, current', [(0.01, 3.0), (0.00925 * 0.56, -480.0)])
def test_loop_field_matches_magpylib(radius, current):
    pts = _points(np.random.default_rng(1), radius * 2)
    pts = pts[np.abs(np.hypot(pts[:, 0], pts[:, 1]) - radius) + np.abs(pts[:, 2]) > 1e-3 * radius]
    ref = magpy.current.Circle(current=current, diameter=2 * radius).getB(pts)
    assert np.max(_relative_error(loop_field(pts, radius, current), ref)) < 1e-6


def test_loop_field_on_axis_is_the_textbook_limit():
    a, current = 0.02, 5.0
    z = np.linspace(-0.1, 0.1, 41)
    b_rho, b_z = loop_field_cylindrical(np.zeros_like(z), z, a, current)
    np.testing.assert_array_equal(b_rho, 0.0)
    np.testing.assert_allclose(b_z, MU0 * a**2 * current / (2 * (a**2 + z**2) ** 1.5), rtol=1e-14)


def test_loop_field_is_smooth_through_the_axis():
    # B_rho grows linearly in rho: B_rho / rho tends to (3/4) mu0 I a^2 z / (a^2 + z^2)^(5/2)
    a, current, z = 0.01, 2.0, 0.013
    rho = np.geomspace(1e-14, 1e-6, 40)  # the rho^2 correction is below 1e-8 here
    b_rho, b_z = loop_field_cylindrical(rho, np.full_like(rho, z), a, current)
    slope = 0.75 * MU0 * current * a**2 * z / (a**2 + z**2) ** 2.5
    np.testing.assert_allclose(b_rho / rho, slope, rtol=1e-7)
    np.testing.assert_allclose(b_z, MU0 * a**2 * current / (2 * (a**2 + z**2) ** 1.5), rtol=1e-8)


def test_loop_field_is_finite_off_the_wire():
    a = 0.01
    pts = np.array([[a * (1 + 1e-9), 0, 0], [a, 0, 1e-9], [0, 0, 0], [1e3, 0, 1e3]])
    assert np.all(np.isfinite(loop_field(pts, a, 1.0)))


@pytest.mark.parametrize(
    'radius, length, polarization', [(0.01, 0.009, 1.1), (0.025, 0.004, -1.1)]
)
def test_sheet_field_matches_magpylib_cylinder(radius, length, polarization):
    pts = _points(np.random.default_rng(2), radius * 2)
    rho = np.hypot(pts[:, 0], pts[:, 1])
    on_sheet = (np.abs(rho - radius) < 1e-6 * radius) & (np.abs(pts[:, 2]) <= length / 2)
    pts = pts[~on_sheet]
    ref = magpy.magnet.Cylinder(
        polarization=(0, 0, polarization), dimension=(2 * radius, length)
    ).getB(pts)
    field = sheet_field(pts, radius, length, polarization * length / MU0)
    assert np.max(_relative_error(field, ref)) < 1e-4


def test_fast_and_accurate_cylinders_agree_far_away():
    # a loop with I = J l / mu0 and the sheet carry the same dipole moment
    radius, length, current = 0.01, 0.009, 1.1 * 0.009 / MU0
    direction = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    errors = []
    for distance in (0.5, 5.0):
        pts = distance * direction[None, :]
        b_loop = loop_field(pts, radius, current)
        b_sheet = sheet_field(pts, radius, length, current)
        errors.append(np.linalg.norm(b_loop - b_sheet) / np.linalg.norm(b_sheet))
    assert errors[0] < 1e-3
    assert errors[1] < errors[0] / 50  # higher multipoles fall off as (size / r)^2


def test_filament_solenoid_far_field_matches_its_own_moment():
    r, length, turns = 0.00925, 0.012, 480
    heights, radii = filament_loops(r, length, turns)
    assert heights.size * radii.size == 456  # the published V2 layout
    current = 1.0
    moment = heights.size * np.sum(np.pi * radii**2) * current
    pts = np.array([[0.0, 0.0, 2.0], [1.2, 0.5, 0.9]])
    total = sum(loop_field(pts - [0, 0, dz], a, current) for dz in heights for a in radii)
    dipole = np.array(
        [
            MU0
            / (4 * np.pi)
            * (
                3 * p * (moment * p[2]) / np.linalg.norm(p) ** 5
                - np.array([0, 0, moment]) / np.linalg.norm(p) ** 3
            )
            for p in pts
        ]
    )
    assert np.max(_relative_error(total, dipole)) < 1e-4
    # smaller than a full-radius solenoid of the same turns: the loops fill the section
    assert moment < turns * np.pi * r**2 * current
