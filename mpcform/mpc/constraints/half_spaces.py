"""What the separation families share: unit normals of a guess path's segments, the start normals
of items that start too close, and the clear test's bound along a path.

A row ``c^T (p - anchor) >= required`` with a unit ``c`` excludes the forbidden set (a ball about
the partner, a grown obstacle core) whatever ``c``; taking ``c`` towards the guess segment's point
nearest the forbidden set makes the guess meet its own row (the separating hyperplane of two convex
sets), which is the rows' recursive feasibility (:mod:`mpcform.mpc.constraints.braking`).
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.world.closest import path_closest, vector_norms

BLOCK = 1024  # pairs whose decoupled rows are built at once (bounds the temporaries' size)
RowPart = tuple[Array, Array, Array, Array, Array]  # (items or labels, coefficients, lower bounds, on, hard)
ClearInputs = tuple[Array, Array, Array, Array | float]
"""The clear test's inputs for m items: distance at the guess's points (S + 1, m), the points it is
measured on (S + 1, m, d), how far the plan strays from the guess (m,), the required distance."""
SegmentTest = tuple[Array, Array, Array | float]
"""The first segment's for m items: distance at its start (m,), along it (m,), the required one."""


def segment_normals(rel: Array, segs: Array | None = None, tail: int = 0) -> Array:
    """Unit normals (m, R, d) per row: the direction to each guess segment's point closest to the
    origin (``rel`` (m, S + 1, d) are the guess's relative positions, ``segs`` (R,) each row's
    segment; without ``segs`` one normal per segment). With more than one braking ``tail`` point
    the last segment is their hull with ``x_H`` (:func:`closest_in_hull`)."""
    normal = path_closest(rel, tail)  # (m, S, d), divided in place
    dist = vector_norms(normal)
    ok = dist > 1e-9
    normal /= np.where(ok, dist, 1.0)[..., None]
    normal[~ok] = np.eye(normal.shape[-1])[0]  # a coincident guess: any fixed unit vector is valid
    return normal if segs is None else np.take(normal, segs, axis=1)


def path_bounds(dist: Array, points: Array, tail: int = 0) -> Array:
    """Lower bounds (S', m) of a 1-Lipschitz distance along each segment of the paths ``points``
    (S + 1, m, d) whose values at the points are ``dist`` (S + 1, m): the larger end's less the
    segment's length; with more than one braking ``tail`` point their hull with the point before
    them last: the largest value less the hull's diameter."""
    head, head_dist = (points, dist) if tail <= 1 else (points[:-tail], dist[:-tail])
    seg = np.maximum(head_dist[:-1], head_dist[1:]) - vector_norms(np.diff(head, axis=0))
    if tail > 1:
        hull = points[-tail - 1 :]
        diameter = vector_norms(hull[:, None] - hull[None]).max(axis=(0, 1))
        seg = np.concatenate([seg, (dist[-tail - 1 :].max(axis=0) - diameter)[None]])
    return seg


def inside(rel0: Array, required: Array | float) -> tuple[Array, Array]:
    """Which items (m,) start inside their required distance (relative start positions ``rel0``
    (m, d)), and their unit start normals (h, d) ``rel0 / |rel0|`` (a fixed axis if coincident)."""
    dist = vector_norms(rel0)
    hard = dist < np.broadcast_to(required, dist.shape)
    c0 = np.zeros((int(hard.sum()), rel0.shape[1]))
    c0[:, 0] = 1.0
    ok = dist[hard] > 1e-12
    c0[ok] = rel0[hard][ok] / dist[hard][ok, None]
    return hard, c0
