"""Cylinder: a disc in the plane, a finite or unbounded vertical pole in space; distance and normal
against a dense sampler of its surface and finite differences, support, escape and keys."""

from __future__ import annotations

import numpy as np
import pytest
from shape_truth import cylinder_surface, fd_gradient, nearest, outside

from mpcform.errors import ValidationError
from mpcform.world.shapes import Cylinder, shape_from_keys

POLE = Cylinder(np.array([0.0, -1.0, 0.75]), 0.2, 1.5, clearance_m=0.1)
MAST = Cylinder(np.array([1.0, 0.5, 1.0]), 0.3, clearance_m=0.1)  # floor to ceiling


def test_a_planar_cylinder_is_a_disc() -> None:
    disc = Cylinder(np.array([1.0, 2.0]), 0.5, clearance_m=0.1)
    pts = outside(np.random.default_rng(0), disc.center_m, 2.0, 200)
    np.testing.assert_allclose(disc.distance_m(pts), np.linalg.norm(pts - disc.center_m, axis=1) - 0.5)
    assert Cylinder.point_core(2) and not Cylinder.point_core(3)
    assert disc.required_core_distance_m(2) == 0.6


def test_a_finite_poles_distance_matches_a_sampler_of_its_surface() -> None:
    pts = outside(np.random.default_rng(1), POLE.center_m, 2.0, 400)
    d = POLE.distance_m(pts)
    far = d > 0.02
    truth = nearest(pts[far], cylinder_surface(POLE.center_m, 0.2, 1.5, 0.005))
    np.testing.assert_allclose(d[far], truth, atol=0.005)


def test_an_unbounded_pole_is_a_disc_at_every_height() -> None:
    pts = outside(np.random.default_rng(2), MAST.center_m, 3.0, 200) + [0.0, 0.0, 50.0]
    radial = np.linalg.norm(pts[:, :2] - MAST.center_m[:2], axis=1)
    np.testing.assert_allclose(MAST.distance_m(pts), np.where(radial > 0.3, radial - 0.3, radial - 0.3))


@pytest.mark.parametrize("pole", [POLE, MAST], ids=["finite", "unbounded"])
def test_the_normal_is_the_distances_gradient(pole: Cylinder) -> None:
    rng = np.random.default_rng(3)
    pts = outside(rng, pole.center_m, 1.5, 300)
    ok = np.abs(np.linalg.norm(pts[:, :2] - pole.center_m[:2], axis=1) - pole.radius_m) > 1e-3
    pts = pts[ok]  # away from the rim, where the gradient jumps inside
    np.testing.assert_allclose(pole.normal(pts), fd_gradient(pole.distance_m, pts), atol=1e-5)


def test_support_is_the_farthest_surface_point_along_a_normal() -> None:
    rng = np.random.default_rng(4)
    normals = rng.normal(size=(60, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    got = Cylinder.support(normals, np.repeat(POLE.params(3)[None], 60, axis=0), 3)
    surface = cylinder_surface(POLE.center_m, 0.2, 1.5, 0.005)
    np.testing.assert_allclose((got * normals).sum(1), (normals @ surface.T).max(axis=1), atol=1e-4)


def test_escape_leaves_by_the_nearest_face() -> None:
    par = np.repeat(POLE.params(3)[None], 2, axis=0)
    pts = POLE.center_m + np.array([[0.15, 0.0, 0.0], [0.0, 0.0, 0.7]])  # near the side, the top cap
    depth, out = Cylinder.escape(pts, par, 3)
    np.testing.assert_allclose(depth, [0.05, 0.05])
    np.testing.assert_allclose(out, [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def test_keys_round_trip_and_bad_heights_name_their_field() -> None:
    for pole in (POLE, MAST):
        again = shape_from_keys(pole.to_keys())
        assert isinstance(again, Cylinder) and again.to_keys() == pole.to_keys()
    for bad in (0.0, -1.0, float("nan"), "tall", True):
        with pytest.raises(ValidationError, match="obstacles.height"):
            Cylinder(np.zeros(3), 0.2, bad)  # type: ignore[arg-type]
