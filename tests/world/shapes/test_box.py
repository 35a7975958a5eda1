"""Box: distance and normal against a dense sampler of its faces and finite differences; support,
escape, keys and the errors that name their field."""

from __future__ import annotations

import numpy as np
import pytest
from shape_truth import box_surface, fd_gradient, nearest, outside

from mpcform.errors import ValidationError
from mpcform.world.shapes import Box, shape_from_keys

CASES = [
    Box(np.array([0.5, -1.0]), np.array([1.5, 0.6]), clearance_m=0.1),
    Box(np.array([1.0, 0.0, 0.5]), np.array([0.6, 2.0, 1.0]), clearance_m=0.2),
]


@pytest.mark.parametrize("box", CASES, ids=["planar", "spatial"])
def test_distance_outside_matches_a_sampler_of_its_faces(box: Box) -> None:
    dim = len(box.center_m)
    pts = outside(np.random.default_rng(dim), box.center_m, 2.0, 400)
    d = box.distance_m(pts)
    far = d > 0.02
    truth = nearest(pts[far], box_surface(box.center_m, box.size_m, 0.005))
    np.testing.assert_allclose(d[far], truth, atol=0.005)


@pytest.mark.parametrize("box", CASES, ids=["planar", "spatial"])
def test_distance_inside_is_minus_the_depth_to_the_nearest_face(box: Box) -> None:
    dim = len(box.center_m)
    rng = np.random.default_rng(10 + dim)
    pts = box.center_m + rng.uniform(-0.49, 0.49, size=(200, dim)) * box.size_m
    depth = (0.5 * box.size_m - np.abs(pts - box.center_m)).min(axis=1)
    np.testing.assert_allclose(box.distance_m(pts), -depth, atol=1e-12)


@pytest.mark.parametrize("box", CASES, ids=["planar", "spatial"])
def test_the_normal_is_the_distances_gradient(box: Box) -> None:
    dim = len(box.center_m)
    pts = outside(np.random.default_rng(20 + dim), box.center_m, 2.0, 300)
    inside = box.center_m + np.random.default_rng(1).uniform(-0.45, 0.45, (100, dim)) * box.size_m
    pts = np.concatenate([pts, inside])
    np.testing.assert_allclose(box.normal(pts), fd_gradient(box.distance_m, pts), atol=1e-5)


def test_support_is_the_farthest_corner_along_a_normal() -> None:
    box = CASES[1]
    rng = np.random.default_rng(3)
    normals = rng.normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    par = np.repeat(box.params(3)[None], 50, axis=0)
    got = Box.support(normals, par, 3)
    faces = box_surface(box.center_m, box.size_m, 0.05)
    np.testing.assert_allclose((got * normals).sum(1), (normals @ faces.T).max(axis=1), atol=1e-12)


def test_keys_round_trip_and_bad_sizes_name_their_field() -> None:
    box = CASES[1]
    again = shape_from_keys(box.to_keys())
    assert isinstance(again, Box) and again.to_keys() == box.to_keys()
    with pytest.raises(ValidationError, match="obstacles.size"):
        Box(np.zeros(2), np.array([1.0, 0.0]))
    with pytest.raises(ValidationError, match=r"obstacles\[0\]\.size"):
        Box(np.zeros(2), np.ones(3)).check_dim(2, "obstacles[0]")
