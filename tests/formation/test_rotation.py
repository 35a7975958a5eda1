"""Rotations: matrices of angles / rotation vectors, their inverse, hat, geodesics, validation."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mpcform.errors import ValidationError
from mpcform.formation.rotation import (
    check_rotation,
    cross_world,
    exp_body,
    geodesic,
    hat,
    omega_size,
    rotation_matrix,
    rotation_param,
)

seeds = st.integers(0, 2**32 - 1)


def random_rotvec(rng):
    """A rotation vector of angle in [0, pi) about a random axis."""
    axis = rng.normal(size=3)
    return rng.uniform(0.0, np.pi - 1e-3) * axis / np.linalg.norm(axis)


def assert_proper(rot):
    np.testing.assert_allclose(rot.T @ rot, np.eye(rot.shape[0]), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0)


def test_omega_size():
    assert (omega_size(2), omega_size(3)) == (1, 3)


@pytest.mark.parametrize("theta", [0.0, 0.3, np.pi / 2, -2.0, 3.0])
def test_planar_rotation_matrix(theta):
    rot = rotation_matrix(2, theta)
    assert_proper(rot)
    np.testing.assert_allclose(rot @ [1.0, 0.0], [np.cos(theta), np.sin(theta)], atol=1e-15)
    assert float(rotation_param(rot)) == pytest.approx(theta)


def test_planar_param_is_wrapped():
    assert float(rotation_param(rotation_matrix(2, 3 * np.pi / 2))) == pytest.approx(-np.pi / 2)


@given(seeds)
def test_spatial_rotation_matrix_is_rodrigues(seed):
    rotvec = random_rotvec(np.random.default_rng(seed))
    rot = rotation_matrix(3, rotvec)
    assert_proper(rot)
    # Rodrigues' formula as independent truth
    phi = np.linalg.norm(rotvec)
    k = hat(rotvec / phi)
    np.testing.assert_allclose(rot, np.eye(3) + np.sin(phi) * k + (1 - np.cos(phi)) * k @ k, atol=1e-12)
    np.testing.assert_allclose(rot @ rotvec, rotvec, atol=1e-12)  # the axis is fixed
    np.testing.assert_allclose(rotation_param(rot), rotvec, atol=1e-9)


@given(seeds)
def test_hat_and_cross_world(seed):
    rng = np.random.default_rng(seed)
    w, q = rng.normal(size=3), rng.normal(size=(4, 3))
    np.testing.assert_allclose(hat(w) @ q[0], np.cross(w, q[0]), atol=1e-14)
    np.testing.assert_allclose(hat(w), -hat(w).T)
    np.testing.assert_allclose(cross_world(w, q), np.cross(w, q), atol=1e-14)
    # planar: omega e_z x (x, y, 0) restricted to the plane
    q2 = q[:, :2]
    expected = np.cross([0.0, 0.0, w[2]], np.column_stack([q2, np.zeros(4)]))[:, :2]
    np.testing.assert_allclose(cross_world(np.array([w[2]]), q2), expected, atol=1e-14)


@given(seeds, st.sampled_from([2, 3]))
def test_geodesic_reaches_the_goal(seed, dim):
    rng = np.random.default_rng(seed)
    params = [rng.uniform(-np.pi, np.pi) if dim == 2 else random_rotvec(rng) for _ in range(2)]
    r0, r1 = (rotation_matrix(dim, p) for p in params)
    axis, phi = geodesic(r0, r1)
    assert 0.0 <= phi <= np.pi + 1e-12
    assert np.linalg.norm(axis) == pytest.approx(1.0)
    np.testing.assert_allclose(exp_body(r0, axis, phi), r1, atol=1e-9)
    np.testing.assert_allclose(exp_body(r0, axis, 0.0), r0, atol=1e-15)


def test_geodesic_of_equal_rotations_is_zero():
    _, phi = geodesic(np.eye(3), np.eye(3))
    assert phi == 0.0


def test_check_rotation_accepts_proper_rotations():
    rot = rotation_matrix(3, [0.1, -0.2, 0.3])
    np.testing.assert_array_equal(check_rotation("r", rot, 3), rot)


@pytest.mark.parametrize(
    ("value", "dim"),
    [
        (np.diag([1.0, -1.0]), 2),  # reflection
        (np.diag([1.0, 1.0, -1.0]), 3),  # reflection
        (-np.eye(3), 3),  # point reflection, det -1
        (1.01 * np.eye(3), 3),  # not orthonormal
        ([[1.0, 0.1], [0.0, 1.0]], 2),  # shear
        (np.eye(3), 2),  # wrong size
        ([[1.0, np.nan], [0.0, 1.0]], 2),
    ],
)
def test_check_rotation_rejects_non_rotations(value, dim):
    with pytest.raises(ValidationError, match="state.rotation"):
        check_rotation("state.rotation", value, dim)


@pytest.mark.parametrize(("dim", "param"), [(2, [0.1, 0.2]), (3, [0.1, 0.2]), (3, [np.inf, 0, 0])])
def test_rotation_matrix_rejects_bad_parameters(dim, param):
    with pytest.raises(ValidationError, match="initial.rotation"):
        rotation_matrix(dim, param, "initial.rotation")
