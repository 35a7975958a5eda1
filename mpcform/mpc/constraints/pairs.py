"""The drone-pair family of the separation rows: ``d_min`` between two drones, joint or decoupled.

About the guess's relative path of each pair, the unit normal of every segment's point closest to
the origin (:func:`~mpcform.mpc.constraints.half_spaces.segment_normals`) gives the half-space row
``c^T W (p_i - p_k) >= d_min + margin`` at both segment ends (joint), or its two halves about the
guess's midpoint, one per drone (decoupled; :mod:`mpcform.mpc.constraints.separation`). The unit
also answers the tests on a plan for its pairs: the clear test's bounds and the first segment's
distances (certification).
"""

from __future__ import annotations

import numpy as np

from mpcform import _jit
from mpcform._validate import Array
from mpcform.formation.geometry import NearPairs
from mpcform.mpc.constraints.family import SeparationFamily
from mpcform.mpc.constraints.half_spaces import (
    BLOCK,
    ClearInputs,
    RowPart,
    SegmentTest,
    inside,
    segment_normals,
)
from mpcform.mpc.constraints.rows import row_ends, row_segments
from mpcform.mpc.settings import MPCSettings
from mpcform.world.closest import closest_on_segments, vector_norms


class PairSeparation(SeparationFamily):
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
        pair, then side k (-c).
        With ``stops`` (n, d), the last row (the braking stop point) of a pair whose ``stops`` meet
        it jointly is split about their midpoint instead (any common split point is safe: the two
        sides add up to the joint row). Each side's rows grow by its drone's share ``grows`` (n,)
        (None: no growth). Built by :func:`mpcform.mpc.constraints.kernels.side_rows` when numba
        is installed (a tail of at most one point), else by numpy."""
        p, r, d = pairs.shape[0], self.segs.shape[0], path.shape[2]
        coeffs, lower, hard = np.empty((2 * p, r, d)), np.empty((2 * p, r)), np.empty(p, dtype=bool)
        half = 0.5 * (self.d_min_m + self.margin_m)
        if _jit.USE and self.tail <= 1:  # the same rows by the compiled loop
            from mpcform.mpc.constraints import kernels

            c = np.ascontiguousarray  # the one layout the kernel is compiled for
            grown = c(np.empty(0) if grows is None else grows)  # empty: no growth, no stop split
            split = c(np.empty((0, d)) if stops is None else stops)
            arrays = (c(p0), c(path), c(pairs), c(self.metric), c(self.segs), c(self.ends))
            bounds = (float(self.d_min_m), half, grown, c(self.grow), split)
            kernels.side_rows(*arrays, *bounds, coeffs, lower, hard)
        else:
            self._numpy_sides(p0, path, pairs, stops, grows, half, coeffs, lower, hard)
        hard2 = np.concatenate([hard, hard])
        lower[hard2, 0] = 0.0
        return np.concatenate([pairs, pairs[:, ::-1]]), coeffs, lower, np.concatenate([on, on]), hard2

    def _numpy_sides(
        self,
        p0: Array,
        path: Array,
        pairs: Array,
        stops: Array | None,
        grows: Array | None,
        half: float,
        coeffs: Array,
        lower: Array,
        hard: Array,
    ) -> None:
        """:meth:`_sides`'s rows into ``coeffs``, ``lower`` and ``hard`` by numpy, :data:`BLOCK`
        pairs at a time (the temporaries stay small); ``lower``'s hard rows are set after."""
        p, r = pairs.shape[0], self.segs.shape[0]
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

    def clear_test(self, guess: Array, pos: Array, i: Array, k: Array) -> ClearInputs:
        """The pairs' ``(i, k)`` distance at the guess (H + 1, m), the relative guess (H + 1, m, d)
        it is measured on, how far their relative positions stray from it (m,), and ``d_min``."""
        g, x = (self.scaled(np.take(v, i, axis=1) - np.take(v, k, axis=1)) for v in (guess, pos))
        return vector_norms(g), g, vector_norms(x - g).max(axis=0, initial=0.0), self.d_min_m

    def first_segment(self, p0: Array, p1: Array, pairs: Array) -> SegmentTest:
        """The ``pairs``' distance at ``p0``, along the first segment to ``p1``, and ``d_min``."""
        i, k = pairs.T
        a, b = self.relative(p0, i, k), self.relative(p1, i, k)
        return vector_norms(a), vector_norms(closest_on_segments(a, b)), self.d_min_m
