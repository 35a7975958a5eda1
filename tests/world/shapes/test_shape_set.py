"""Many obstacles at once: distances agree with each shape's own, and the planner's separating
half-spaces exclude every grown shape while the guess meets its own row, for every kind mixed in one
set, with and without a braking tail's hull."""

from __future__ import annotations

import numpy as np
import pytest
from shape_truth import box_surface, cylinder_surface

from mpcform.world.closest import path_closest
from mpcform.world.shapes import Box, Cylinder, Sphere
from mpcform.world.shapes.shape_set import ShapeSet

SPATIAL = (
    Sphere(np.array([0.0, 0.0, 1.0]), 0.4, 0.2),
    Cylinder(np.array([2.0, 0.0, 1.0]), 0.3, 1.5, 0.2),
    Cylinder(np.array([-2.0, 1.0, 0.0]), 0.2, clearance_m=0.1),
    Box(np.array([0.0, 2.0, 0.5]), np.array([1.0, 0.5, 1.0]), 0.2),
)
PLANAR = (
    Sphere(np.array([0.0, 0.0]), 0.4, 0.2),
    Cylinder(np.array([2.0, 0.0]), 0.3, clearance_m=0.2),
    Box(np.array([0.0, 2.0]), np.array([1.0, 0.5]), 0.2),
)


def grown_samples(shape: Sphere | Cylinder | Box, dim: int) -> np.ndarray:
    """Points on the surface of the core (a sphere's centre grown by its radius is sampled too)."""
    if isinstance(shape, Box):
        return box_surface(shape.center_m, shape.size_m, 0.05)
    if isinstance(shape, Cylinder) and dim == 3:
        return cylinder_surface(shape.center_m, shape.radius_m, min(shape.height_m, 4.0), 0.05)
    return shape.center_m[None]  # a point core


@pytest.mark.parametrize(("shapes", "dim"), [(SPATIAL, 3), (PLANAR, 2)], ids=["spatial", "planar"])
def test_distances_agree_with_each_shapes_own(shapes: tuple, dim: int) -> None:
    s = ShapeSet(shapes, dim)
    pts = np.random.default_rng(0).uniform(-3, 3, (300, dim))
    own = np.stack([sh.distance_m(pts) for sh in shapes], axis=1)
    core = s.core_distances(pts)
    outside = own > 0
    np.testing.assert_allclose(
        core[outside] - np.broadcast_to(s.rounding_m, own.shape)[outside], own[outside]
    )
    np.testing.assert_array_equal(s.required_m, s.rounding_m + [sh.clearance_m for sh in shapes])


@pytest.mark.parametrize("tail", [0, 1, 3])
@pytest.mark.parametrize(("shapes", "dim"), [(SPATIAL, 3), (PLANAR, 2)], ids=["spatial", "planar"])
def test_separators_exclude_the_grown_shape_and_the_guess_meets_its_row(
    shapes: tuple, dim: int, tail: int
) -> None:
    s = ShapeSet(shapes, dim)
    rng = np.random.default_rng(tail)
    k, steps = 40, 10
    items = rng.integers(0, len(shapes), k)
    path = rng.uniform(-3, 3, (k, 1, dim)) + np.cumsum(rng.uniform(-0.3, 0.3, (k, steps + 1, dim)), axis=1)
    normal, anchor = s.separators(path, items, tail)
    segments = path_closest(path - path[:, :1], tail).shape[1]  # as the pairs' rows count them
    assert normal.shape == (k, segments, dim) and anchor.shape[0] == k
    np.testing.assert_allclose(np.linalg.norm(normal, axis=-1), 1.0)
    for j in range(k):
        shape = shapes[items[j]]
        core = grown_samples(shape, dim)
        # the core lies behind each plane, so n^T (p - anchor) >= rounding + clearance excludes
        # the grown shape
        along = np.einsum("sd,sNd->sN", normal[j], core[None] - anchor[j][:, None])
        assert along.max() <= 1e-9, (shape.kind, along.max())
        # the guess's segment meets its own row: its least n^T (p - anchor) is the segment's gap
        gap = s.item_segment_distances(path[j, :-1], path[j, 1:], np.full(steps, items[j]))
        heads = segments - (1 if tail > 1 else 0)
        ends = np.minimum(
            np.einsum("sd,sd->s", normal[j, :heads], path[j, :heads] - anchor[j, :heads]),
            np.einsum("sd,sd->s", normal[j, :heads], path[j, 1 : heads + 1] - anchor[j, :heads]),
        )
        apart = gap[:heads] > 1e-6  # a segment through the core leaves by its escape instead
        np.testing.assert_allclose(ends[apart], gap[:heads][apart], atol=1e-6)
        assert np.all(ends[~apart] <= 1e-9)
