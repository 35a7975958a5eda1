"""Closest points between a convex core and a segment or a hull, from the core's projection alone.

For a core that is not one point (:meth:`mpcform.world.shapes.base.Shape.point_core`), the distance
from a segment's point ``s(t) = a + t (b - a)`` to the core is convex in ``t``, so a golden-section
search finds its least value (:func:`segment_gaps`); the pair it returns, ``s(t)`` and its projection
``k``, is exact whatever ``t``: ``k`` is the core's support point along ``s - k``, so the half-space
the planner writes with it excludes the core. The hull of a braking tail's points is met by
alternating projections (:func:`hull_gaps`: the hull's nearest point to ``k``, then the core's to
that), which converge to a closest pair of two disjoint convex sets.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mpcform._validate import Array
from mpcform.world.closest import closest_in_hull

Project = Callable[[Array], Array]  # points (k, d) -> the core's nearest points (k, d)
GOLDEN_STEPS = 60
"""Golden-section steps: the segment's parameter to 0.618^60 ~ 3e-13 of its length."""
HULL_STEPS = 24
"""Alternating projections between a hull and the core (each halves the gap's error or better)."""
_INVERSE_PHI = (np.sqrt(5.0) - 1.0) / 2.0


def segment_gaps(start: Array, end: Array, project: Project) -> tuple[Array, Array]:
    """For each segment ``start -> end`` (k, d): ``(s - c, c)``, ``s`` the segment's point nearest the
    core and ``c`` its projection onto it (both (k, d))."""
    delta = end - start

    def gap(t: Array) -> Array:
        point = start + t[:, None] * delta
        return np.linalg.norm(point - project(point), axis=1)

    lo, hi = np.zeros(start.shape[0]), np.ones(start.shape[0])
    x1, x2 = hi - _INVERSE_PHI, lo + _INVERSE_PHI
    f1, f2 = gap(x1), gap(x2)
    for _ in range(GOLDEN_STEPS):
        left = f1 <= f2  # the least value lies in [lo, x2], else in [x1, hi]
        hi, lo = np.where(left, x2, hi), np.where(left, lo, x1)
        new = np.where(left, hi - _INVERSE_PHI * (hi - lo), lo + _INVERSE_PHI * (hi - lo))
        value = gap(new)
        x1, x2, f1, f2 = (
            np.where(left, new, x2),
            np.where(left, x1, new),
            np.where(left, value, f2),
            np.where(left, f1, value),
        )
    ends = np.stack([np.zeros_like(lo), 0.5 * (lo + hi), np.ones_like(lo)])
    values = np.stack([gap(t) for t in ends])
    best = ends[np.argmin(values, axis=0), np.arange(lo.shape[0])]
    point = start + best[:, None] * delta
    core = project(point)
    return point - core, core


def hull_gaps(points: Array, project: Project) -> tuple[Array, Array]:
    """For each hull of ``points`` (k, T, d): ``(s - c, c)`` for a closest pair, ``s`` in the hull
    and ``c`` in the core (alternating projections from the core's point nearest the hull's mean)."""
    core = project(points.mean(axis=1))
    for _ in range(HULL_STEPS):
        near = core + closest_in_hull(points - core[:, None])
        core = project(near)
    near = core + closest_in_hull(points - core[:, None])
    return near - core, core


def outline(points: Array, radius_m: float, sides: int = 64) -> Array:
    """The convex hull (k, 2), counter-clockwise, of ``points`` (m, 2) grown by ``radius_m``."""
    from scipy.spatial import ConvexHull, QhullError

    ang = 2.0 * np.pi * np.arange(sides) / sides
    disc = radius_m * np.column_stack([np.cos(ang), np.sin(ang)])
    grown = (points[:, None, :] + disc[None]).reshape(-1, 2) if radius_m > 0 else points
    if grown.shape[0] < 3:
        return grown
    try:
        hull = ConvexHull(grown)
    except QhullError:  # a degenerate (flat) outline: its points as they are
        return grown
    return grown[hull.vertices]
