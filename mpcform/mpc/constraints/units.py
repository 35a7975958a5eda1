"""The two units of the separation rows (:mod:`mpcform.mpc.constraints.separation`): drone pairs
(:class:`PairSeparation`, joint or decoupled) and obstacles (:class:`ObstacleSeparation`), each
building its rows about the guess and answering the tests on a plan for its items; with the
geometry they share (:func:`segment_normals`, :func:`inside`).
"""

from __future__ import annotations

from functools import lru_cache
from itertools import combinations

import numpy as np

from mpcform._validate import Array
from mpcform.formation.geometry import NearPairs, closest_on_segments, vector_norms
from mpcform.mpc.constraints.rows import row_ends, row_segments
from mpcform.mpc.settings import MPCSettings
from mpcform.world.obstacles import SphereObstacle, obstacle_arrays

BLOCK = 1024  # pairs whose decoupled rows are built at once (bounds the temporaries' size)
RowPart = tuple[Array, Array, Array, Array, Array]  # (items or labels, coefficients, lower bounds, on, hard)
Test = tuple[Array, Array, Array | float]  # (relative guess, relative positions, required distance)


def segment_normals(rel: Array, segs: Array | None = None, tail: int = 0) -> Array:
    """Unit normals (m, R, d) per row: the direction to each guess segment's point closest to the
    origin (``rel`` (m, S + 1, d) are the guess's relative positions, ``segs`` (R,) each row's
    segment; without ``segs`` one normal per segment). With more than one braking ``tail`` point
    the last segment is their hull with ``x_H`` (:func:`closest_in_hull`)."""
    if tail > 1:
        head = closest_on_segments(rel[:, : -tail - 1], rel[:, 1:-tail])
        normal = np.concatenate([head, closest_in_hull(rel[:, -tail - 1 :])[:, None]], axis=1)
    else:
        normal = closest_on_segments(rel[:, :-1], rel[:, 1:])  # (m, H, d), divided in place
    dist = vector_norms(normal)
    ok = dist > 1e-9
    normal /= np.where(ok, dist, 1.0)[..., None]
    normal[~ok] = np.eye(normal.shape[-1])[0]  # a coincident guess: any fixed unit vector is valid
    return normal if segs is None else np.take(normal, segs, axis=1)


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


class PairSeparation:
    """``d_min`` [m] between drone pairs in the metric ``W = diag(metric)``, joint or decoupled."""

    def __init__(
        self, d_min_m: float, metric: Array, settings: MPCSettings, tail: int = 0, grow: Array | None = None
    ) -> None:
        self.d_min_m, self.metric, self.margin_m = d_min_m, metric, settings.margin_m
        self.unit_metric = bool(np.all(metric == 1.0))  # W = I: no scaling
        self.joint = settings.coupling == "joint"
        self.tail = tail  # the braking tail's points (:mod:`mpcform.mpc.constraints.tail`)
        self.segs, self.ends = row_segments(settings.horizon, tail), row_ends(settings.horizon, tail)
        self.grow = np.zeros(self.ends.shape) if grow is None else grow  # per drone and row (R,) [m]
        self.near = NearPairs()  # the clear test's neighbour list, kept between steps

    def relative(self, points: Array, i: Array, k: Array) -> Array:
        """``W (p_i - p_k)`` for positions (..., n, d): (..., P, d)."""
        return self.scaled(points[..., i, :] - points[..., k, :])

    def scaled(self, v: Array) -> Array:
        """``W v`` for vectors (..., d) (``v`` itself when ``W = I``)."""
        return v if self.unit_metric else v * self.metric

    def rows(
        self,
        p0: Array,
        path: Array,
        pairs: Array,
        on: Array,
        stops: Array | None = None,
        growing: Array | None = None,
    ) -> tuple[RowPart | None, RowPart | None]:
        """The joint rows, or the decoupled one-drone rows (side i of every pair, then side k), of
        ``pairs`` (P, 2) about the guess ``path`` (n, H + 1, d) (drone-major); ``stops``, ``growing``:
        see :meth:`mpcform.mpc.constraints.separation.Separation.rows`."""
        if not self.joint:
            return None, self._sides(p0, path, pairs, on, stops, growing)
        i, k = pairs[:, 0], pairs[:, 1]
        rel = self.scaled(path[i] - path[k])  # (P, H + 1, d), metric space
        coeffs = self.scaled(segment_normals(rel, self.segs, self.tail))  # (P, R, d), world coordinates
        hard, c0 = inside(rel[:, 0], self.d_min_m)
        coeffs[hard, 0] = self.scaled(c0)
        lower = self.d_min_m + self.margin_m - np.einsum("prd,pd->pr", coeffs, p0[i] - p0[k])
        if growing is not None:
            lower += (growing[i] + growing[k])[:, None] * self.grow
        lower[hard, 0] = 0.0
        return (pairs, coeffs, lower, on, hard), None

    def _sides(
        self, p0: Array, path: Array, pairs: Array, on: Array, stops: Array | None, grows: Array | None
    ) -> RowPart:
        """The decoupled rows: two per-drone rows about the guess's midpoint ``m_e`` at each row's
        position step, ``+-c^T (p0_side - m_e) >= (d_min + margin) / 2``, side i (+c) of every
        pair, then side k (-c); built :data:`BLOCK` pairs at a time (the temporaries stay small).
        With ``stops`` (n, d), the last row (the braking stop point) of a pair whose ``stops`` meet
        it jointly is split about their midpoint instead (any common split point is safe: the two
        sides add up to the joint row). Each side's rows grow by its drone's share ``grows`` (n,)
        (None: no growth)."""
        p, r, d = pairs.shape[0], self.segs.shape[0], path.shape[2]
        coeffs, lower, hard = np.empty((2 * p, r, d)), np.empty((2 * p, r)), np.empty(p, dtype=bool)
        half = 0.5 * (self.d_min_m + self.margin_m)
        plain = np.full((1, r), half)  # every side's bound without growth (1, R)
        for a in range(0, p, BLOCK):
            b = min(a + BLOCK, p)
            i, k = pairs[a:b, 0], pairs[a:b, 1]
            g_i, g_k = path[i], path[k]  # (B, H + 1, d)
            rel = self.scaled(g_i - g_k)  # metric space
            normal = self.scaled(segment_normals(rel, None, self.tail))  # (B, H, d), world coordinates
            np.take(normal, self.segs, axis=1, out=coeffs[a:b])
            hard[a:b], c0 = inside(rel[:, 0], self.d_min_m)
            coeffs[a:b][hard[a:b], 0] = self.scaled(c0)
            np.negative(coeffs[a:b], out=coeffs[p + a : p + b])
            mid = np.add(g_i, g_k, out=g_i)  # the midpoints (B, H + 1, d), in place
            mid *= 0.5
            mid = np.take(mid, self.ends, axis=1)  # at each row's position step (B, R, d)
            bounds = [plain] * 2 if grows is None else [half + grows[s][:, None] * self.grow for s in (i, k)]
            if stops is not None:  # the stop row (R - 2): its split towards the rollout's
                g_stop = path[i, -1], path[k, -1]  # (g_i holds the midpoints now)
                halves = bounds[0][:, -2], bounds[1][:, -2]
                mid[:, -2] = self._stop_split(
                    coeffs[a:b, -2], *g_stop, mid[:, -2], stops[i], stops[k], *halves
                )
            sides = ((i, lower[a:b], np.subtract), (k, lower[p + a : p + b], np.add))
            for (side, out, fix), bound in zip(sides, bounds, strict=True):
                gap = p0[side][:, None] - mid  # -(-c)^T gap = +c^T gap on side k
                fix(bound, np.einsum("prd,prd->pr", coeffs[a:b], gap), out=out)
        hard2 = np.concatenate([hard, hard])
        lower[hard2, 0] = 0.0
        return np.concatenate([pairs, pairs[:, ::-1]]), coeffs, lower, np.concatenate([on, on]), hard2

    def _stop_split(
        self,
        c: Array,
        g_i: Array,
        g_k: Array,
        m_g: Array,
        s_i: Array,
        s_k: Array,
        half_i: Array,
        half_k: Array,
    ) -> Array:
        """Split points (B, d) of the stop rows ``c`` (B, d): from the guess's midpoint ``m_g`` as
        far towards the rollout's stop points' ``(s_i + s_k) / 2`` as the guess's stop points
        ``g_i``, ``g_k`` still meet both sides (so the shifted plan stays feasible: a formation
        speeding up together moves both sides of a split, and the guess's midpoint would throttle
        it). Any common split point is safe: the two sides add up to the joint row. ``half_i``,
        ``half_k`` (B,) (or (1,)): each side's bound on the stop row."""
        step = 0.5 * (s_i + s_k) - m_g
        along, at = np.einsum("pd,pd->p", c, step), np.einsum("pd,pd->p", c, m_g)
        room = np.where(
            along > 0,
            np.einsum("pd,pd->p", c, g_i) - half_i - at,
            np.einsum("pd,pd->p", c, g_k) + half_k - at,
        )
        t = np.clip(np.divide(room, along, out=np.ones_like(along), where=along != 0), 0.0, 1.0)
        return m_g + t[:, None] * step

    def doubtful(self, p0: Array, spread: Array) -> tuple[Array, Array, Array]:
        """The pairs ``(i, k)`` (of the neighbour list) the spread bound of :meth:`Separation.clear`
        leaves in doubt, and by how much their start distance clears it (negative)."""
        scaled = self.scaled(p0)  # the metric only shrinks lengths: world spreads bound it
        need = self.d_min_m + self.margin_m + 2.0 * self.grow.max()
        i, k = self.near.within(scaled, need + 2.0 * spread.max()).T
        gap = vector_norms(np.take(scaled, i, axis=0) - np.take(scaled, k, axis=0))
        clearance = gap - np.take(spread, i) - np.take(spread, k)
        near = clearance < need
        if not near.any():  # the common case: every pair clear
            return i[:0], k[:0], clearance[:0]
        return i[near], k[near], clearance[near] - need

    def clear_test(self, guess: Array, pos: Array, i: Array, k: Array) -> Test:
        """Relative guess and positions (H + 1, m, d) of the pairs ``(i, k)``."""
        g, x = (self.scaled(np.take(v, i, axis=1) - np.take(v, k, axis=1)) for v in (guess, pos))
        return g, x, self.d_min_m

    def first_segment(self, p0: Array, p1: Array, pairs: Array) -> Test:
        """Relative positions of ``pairs`` at the start and the end of the first segment."""
        i, k = pairs.T
        return self.relative(p0, i, k), self.relative(p1, i, k), self.d_min_m


class ObstacleSeparation:
    """Drones keep ``required_m`` (m,) [m] from the obstacles' centres ``center_m`` (m, d): the
    radius plus each obstacle's resolved clearance (:func:`mpcform.world.obstacles.resolve_clearances`)."""

    def __init__(
        self,
        obstacles: tuple[SphereObstacle, ...],
        settings: MPCSettings,
        tail: int = 0,
        grow: Array | None = None,
    ) -> None:
        self.center_m, self.required_m = obstacle_arrays(obstacles)
        self.margin_m, self.tail = settings.margin_m, tail  # the braking tail's points
        self.segs = row_segments(settings.horizon, tail)
        self.grow = np.zeros(self.segs.shape) if grow is None else grow  # per drone and row (R,) [m]

    def rows(self, p0: Array, path: Array, items: Array, on: Array, growing: Array | None = None) -> RowPart:
        """One-drone rows of the ``(drone, obstacle)`` items (O, 2) about the guess ``path``
        (n, H + 1, d) (drone-major), grown by each drone's share ``growing`` (n,)."""
        drone, ob = items[:, 0], items[:, 1]
        center, required = self.center_m[ob], self.required_m[ob]
        coeffs = segment_normals(path[drone] - center[:, None], self.segs, self.tail)
        hard, c0 = inside(p0[drone] - center, required)
        coeffs[hard, 0] = c0
        lower = required[:, None] + self.margin_m - np.einsum("ord,od->or", coeffs, p0[drone] - center)
        if growing is not None:
            lower += growing[drone][:, None] * self.grow
        lower[hard, 0] = 0.0
        return np.column_stack([drone, -1 - ob]), coeffs, lower, on, hard

    def doubtful(self, p0: Array, spread: Array) -> tuple[Array, Array, Array]:
        """The ``(drone, obstacle)`` items that the per-drone spread bound (see
        :meth:`Separation.clear`) leaves in doubt, and by how much they clear it (negative)."""
        gap = vector_norms(p0[:, None] - self.center_m) - self.required_m - spread[:, None]
        need = self.margin_m + self.grow.max()
        i, m = np.nonzero(gap < need)
        return i, m, gap[i, m] - need

    def clear_test(self, guess: Array, pos: Array, i: Array, m: Array) -> Test:
        """Guess and positions (H + 1, m, d) of the items' drones relative to their obstacle."""
        center = self.center_m[m]
        return np.take(guess, i, axis=1) - center, np.take(pos, i, axis=1) - center, self.required_m[m]

    def first_segment(self, p0: Array, p1: Array, items: Array) -> Test:
        """Positions of the ``items``' drones relative to their obstacle at both ends of the first segment."""
        i, m = items.T
        return p0[i] - self.center_m[m], p1[i] - self.center_m[m], self.required_m[m]


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
