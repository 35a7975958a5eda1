"""Closest pairs of a core that is not a point: golden section on a segment and alternating
projections on a hull, against a dense sampler of the segment and of the hull."""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from mpcform.world.shapes import Box, Cylinder
from mpcform.world.shapes.convex import hull_gaps, outline, segment_gaps

BOX = Box(np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.6, 2.0]))
POLE = Cylinder(np.array([0.5, 0.5, 1.0]), 0.3, 1.2)


def projector(shape, count):  # type: ignore[no-untyped-def]
    par = np.repeat(shape.params(3)[None], count, axis=0)
    return lambda p: type(shape).project(p, par[: len(p)], 3)


def test_a_segments_gap_is_the_least_over_its_points() -> None:
    rng = np.random.default_rng(0)
    for shape in (BOX, POLE):
        a, b = rng.uniform(-2, 3, (200, 3)), rng.uniform(-2, 3, (200, 3))
        gap, core = segment_gaps(a, b, projector(shape, 200))
        t = np.linspace(0.0, 1.0, 20001)
        dense = a[:, None] + t[None, :, None] * (b - a)[:, None]
        flat = dense.reshape(-1, 3)
        dist = np.linalg.norm(flat - projector(shape, len(flat))(flat), axis=1).reshape(200, -1)
        found = np.linalg.norm(gap, axis=1)
        assert np.all(found <= dist.min(axis=1) + 1e-9)  # never worse than a sampled point
        np.testing.assert_allclose(found, dist.min(axis=1), atol=1e-6)  # 2.5e-4 m apart
        np.testing.assert_allclose(projector(shape, 200)(core), core, atol=1e-12)  # in the core


def test_a_hulls_gap_is_the_least_over_its_points() -> None:
    """Against the least distance over the hull's weights, found by SLSQP on the simplex."""
    rng = np.random.default_rng(1)
    pts = rng.uniform(-2, 3, (20, 1, 3)) + rng.uniform(-0.3, 0.3, (20, 4, 3))  # small hulls of 4
    gap, core = hull_gaps(pts, projector(POLE, 20))
    one = projector(POLE, 1)
    for hull, found in zip(pts, np.linalg.norm(gap, axis=1), strict=True):

        def dist(w: np.ndarray, hull: np.ndarray = hull) -> float:
            x = (w @ hull)[None]
            return float(np.linalg.norm(x - one(x)))

        best = minimize(
            dist,
            np.full(4, 0.25),
            method="SLSQP",
            bounds=[(0.0, 1.0)] * 4,
            constraints={"type": "eq", "fun": lambda w: w.sum() - 1.0},
            options={"ftol": 1e-12},
        )
        assert found <= best.fun + 1e-6 and found >= best.fun - 1e-4
    np.testing.assert_allclose(projector(POLE, 20)(core), core, atol=1e-12)


def test_an_outline_is_the_hull_grown() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    ring = outline(square, 0.5)
    d = np.linalg.norm(ring - np.clip(ring, 0.0, 1.0), axis=1)
    np.testing.assert_allclose(d, 0.5, atol=1e-12)
    e1, e2 = ring[1] - ring[0], ring[2] - ring[1]
    assert e1[0] * e2[1] - e1[1] * e2[0] > 0  # counter-clockwise
