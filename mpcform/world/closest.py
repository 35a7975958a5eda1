"""Closest points to the origin: on straight segments (:func:`closest_on_segments`), on the hull of a
few points (:func:`closest_in_hull`), and on each segment of a guess path, its braking tail's hull
last (:func:`path_closest`); with the norms they are measured by. The planner's separation rows
and every safety measure take their normals and distances from these."""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations

import numpy as np

from mpcform._validate import Array


def closest_on_segments(start: Array, end: Array) -> Array:
    """Point closest to the origin on each segment ``start -> end``; inputs and output (..., d)."""
    delta = end - start
    den = np.einsum("...j,...j->...", delta, delta)
    tau = np.negative(np.einsum("...j,...j->...", start, delta))
    tau /= np.where(den > 0, den, 1.0)
    np.clip(tau, 0.0, 1.0, out=tau)
    delta *= tau[..., None]
    delta += start
    return delta


def squared_norms(v: Array, overwrite: bool = False) -> Array:
    """Squared Euclidean norms over the last axis of ``v`` (..., d), summed in order (faster than
    ``np.einsum("...d,...d")`` over a short axis); ``overwrite``: ``v`` holds the squares after."""
    squares = np.square(v, out=v if overwrite else None)
    sq = squares[..., 0]
    for a in range(1, v.shape[-1]):
        sq += squares[..., a]
    return sq


def vector_norms(v: Array) -> Array:
    """Euclidean norms over the last axis of ``v`` (..., d), summed in order: bitwise
    ``np.linalg.norm(v, axis=-1)``, without its slow reduction over a short axis."""
    return np.sqrt(squared_norms(v))


def closest_in_hull(points: Array) -> Array:
    """The point (m, d) of each hull of ``points`` (m, K, d) closest to the origin (d <= 3): the
    nearest over every edge and, in 3-D, every triangle's interior (it lies on a face of at most
    two dimensions; the origin itself when it lies inside a 2-D hull's triangle is not sought:
    no row can keep an item whose guess covers it anyway). A 3-D hull of more than
    :data:`FACES_AT_ONCE` points is searched by :func:`_descent` instead."""
    if points.shape[2] == 3 and points.shape[1] > FACES_AT_ONCE:
        return _descent(points)
    best, _ = _candidates(points)
    pick = np.argmin(np.einsum("med,med->me", best, best), axis=1)
    return np.take_along_axis(best, pick[:, None, None], axis=1)[:, 0]


def _candidates(points: Array) -> tuple[Array, Array]:
    """Each face's point closest to the origin (m, F, d) and the faces (F, 3) as point indices: every
    edge (its end repeated), then in 3-D every triangle (an interior point only where it is one, else
    the first edge's point)."""
    a, b = np.triu_indices(points.shape[1], 1)
    best = closest_on_segments(points[:, a], points[:, b])  # (m, E, d)
    faces = np.column_stack([a, b, b])
    if points.shape[2] == 3 and points.shape[1] > 2:
        i, j, k = _triangles(points.shape[1])
        p, e1, e2 = points[:, i], points[:, j] - points[:, i], points[:, k] - points[:, i]
        g11, g12, g22 = (np.einsum("mtd,mtd->mt", u, v) for u, v in ((e1, e1), (e1, e2), (e2, e2)))
        r1, r2 = np.einsum("mtd,mtd->mt", e1, p), np.einsum("mtd,mtd->mt", e2, p)
        det = g11 * g22 - g12**2
        ok = det > 1e-12 * (g11 * g22 + 1e-300)
        safe = np.where(ok, det, 1.0)
        s, t = (g12 * r2 - g22 * r1) / safe, (g12 * r1 - g11 * r2) / safe  # min |p + s e1 + t e2|
        inner = ok & (s >= 0.0) & (t >= 0.0) & (s + t <= 1.0)
        face = p + s[..., None] * e1 + t[..., None] * e2
        best = np.concatenate([best, np.where(inner[..., None], face, best[:, :1])], axis=1)
        faces = np.vstack([faces, np.column_stack([i, j, k])])
    return best, faces


FACES_AT_ONCE = 8
"""A 3-D hull of more points is searched by :func:`_descent`: its C(K, 3) triangles at once took
three quarters of a spatial quadrotor swarm's planning time (9,139 of them for 39 tail points)."""
DESCENT_STEPS = 64  # at most this many face updates (a few are needed; an origin inside may cycle)
DESCENT_TOL = 1e-12  # a vertex less than this share of |x|^2 below x along x is not a descent


def _descent(points: Array) -> Array:
    """:func:`closest_in_hull` by Wolfe's (GJK's) descent: the closest point ``x`` of a face of at
    most three points, then of that face and the vertex least along ``x``, until no vertex lies
    below ``x`` along it (then ``x`` is the hull's closest point)."""
    m = points.shape[0]
    at = np.arange(m)
    near = np.argmin(np.einsum("mkd,mkd->mk", points, points), axis=1)
    x, face = points[at, near], np.repeat(near[:, None], 3, axis=1)
    for _ in range(DESCENT_STEPS):
        dots = np.einsum("mkd,md->mk", points, x)
        w = np.argmin(dots, axis=1)
        xx = np.einsum("md,md->m", x, x)
        todo = np.flatnonzero(xx - dots[at, w] > DESCENT_TOL * xx)
        if todo.size == 0:
            break
        corners = np.concatenate([face[todo], w[todo, None]], axis=1)  # (t, 4)
        best, faces = _candidates(points[todo[:, None], corners])
        pick = np.argmin(np.einsum("tfd,tfd->tf", best, best), axis=1)
        x[todo] = best[np.arange(todo.size), pick]
        face[todo] = np.take_along_axis(corners, faces[pick], axis=1)
    return x


@lru_cache(maxsize=16)
def _triangles(k: int) -> Array:
    """Every triple of ``k`` points' indices (3, C(k, 3)) (the hull's faces are among them)."""
    return np.array(list(combinations(range(k), 3))).T


def path_closest(rel: Array, tail: int = 0) -> Array:
    """The point (m, S, d) of each segment of the paths ``rel`` (m, S + 1, d) closest to the origin;
    with more than one braking ``tail`` point the last segment is their hull with the point before
    them (:func:`closest_in_hull`)."""
    if tail > 1:
        head = closest_on_segments(rel[:, : -tail - 1], rel[:, 1:-tail])
        return np.concatenate([head, closest_in_hull(rel[:, -tail - 1 :])[:, None]], axis=1)
    return closest_on_segments(rel[:, :-1], rel[:, 1:])
