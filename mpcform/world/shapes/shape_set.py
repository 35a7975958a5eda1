"""Many obstacles at once: the distances, closest pairs and separating half-spaces every consumer needs.

A :class:`ShapeSet` holds resolved obstacles of any kinds (:mod:`mpcform.world.shapes`) in one
numbering, grouped by kind for the kinds' batch kernels. Item-wise questions take ``items`` (k,),
an obstacle index per point, path or segment. Point cores (spheres, planar cylinders) take the
closed forms of :mod:`mpcform.world.closest`, so a set of spheres gives the numbers it always
gave; other cores take :mod:`mpcform.world.shapes.convex`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from mpcform._validate import Array
from mpcform.world.closest import closest_on_segments, path_closest, vector_norms
from mpcform.world.shapes.base import Shape
from mpcform.world.shapes.convex import hull_gaps, segment_gaps

DEGENERATE_M = 1e-9  # a closest pair nearer than this gives no direction: the core's escape instead


class ShapeSet:
    """The obstacles ``shapes`` (clearances resolved) of a ``dim``-dimensional run."""

    def __init__(self, shapes: Sequence[Shape], dim: int) -> None:
        self.shapes, self.dim = tuple(shapes), dim
        for k, shape in enumerate(self.shapes):
            shape.check_dim(dim, f"obstacles[{k}]")
        self.clearance_m = np.array([s.resolved_clearance_m for s in self.shapes])
        kinds: dict[type[Shape], list[int]] = {}
        for k, shape in enumerate(self.shapes):
            kinds.setdefault(type(shape), []).append(k)
        self.groups = [
            (kind, np.array(idx, dtype=np.intp), np.array([self.shapes[k].params(dim) for k in idx]))
            for kind, idx in kinds.items()
        ]
        self.rounding_m = np.zeros(len(self.shapes))
        for kind, idx, par in self.groups:
            self.rounding_m[idx] = kind.rounding(par, dim)
        self.required_m = self.rounding_m + self.clearance_m  # kept from the core [m]
        self.point_cores = all(kind.point_core(dim) for kind, _, _ in self.groups)
        self.centers_m = np.zeros((len(self.shapes), dim))  # the point cores' centres
        for kind, idx, par in self.groups:
            if kind.point_core(dim):
                self.centers_m[idx] = par[:, :dim]

    def __len__(self) -> int:
        return len(self.shapes)

    def subset(self, items: Array) -> ShapeSet:
        """The obstacles ``items`` (k,), in that order."""
        return ShapeSet([self.shapes[k] for k in np.asarray(items).tolist()], self.dim)

    # ---- every point against every obstacle --------------------------------------------------
    def core_distances(self, points_m: Array) -> Array:
        """Distance (..., m) [m] of points (..., d) to each obstacle's core."""
        if self.point_cores:
            return vector_norms(points_m[..., None, :] - self.centers_m)
        flat = points_m.reshape(-1, self.dim)
        out = np.empty((flat.shape[0], len(self)))
        for k in range(len(self)):
            out[:, k] = self.gaps(flat, np.full(flat.shape[0], k))[0]
        return out.reshape(points_m.shape[:-1] + (len(self),))

    def segment_distances(self, start_m: Array, end_m: Array) -> Array:
        """Distance (N, m) [m] of each segment ``start -> end`` (N, d) to each obstacle's core."""
        out = np.empty((start_m.shape[0], len(self)))
        for k in range(len(self)):
            out[:, k] = self.item_segment_distances(start_m, end_m, np.full(start_m.shape[0], k))
        return out

    # ---- item-wise: one obstacle per point, segment or path ------------------------------------
    def gaps(self, points_m: Array, items: Array) -> tuple[Array, Array]:
        """Per item: the distance (k,) of its point (k, d) to its obstacle's core, and the core's
        nearest point (k, d) (a point core: its centre)."""
        return self._each(items, points_m, lambda kind, par, p: kind.project(p, par, self.dim), distance=True)

    def item_segment_distances(self, start_m: Array, end_m: Array, items: Array) -> Array:
        """Distance (k,) of each item's segment ``start -> end`` (k, d) to its obstacle's core."""
        out = np.empty(start_m.shape[0])
        for kind, sel, par in self.by_kind(items):
            a, b = start_m[sel], end_m[sel]
            if kind.point_core(self.dim):
                c = par[:, : self.dim]
                out[sel] = vector_norms(closest_on_segments(a - c, b - c))
            else:
                out[sel] = vector_norms(segment_gaps(a, b, self._projector(kind, par))[0])
        return out

    def start_normals(self, points_m: Array, items: Array) -> tuple[Array, Array]:
        """Per item: the distance (k,) of its point to its obstacle's core and the unit direction
        (k, d) away from the core there (the distance's gradient; a point core's centre itself:
        the first axis; a point inside another core: its escape)."""
        rel, core = self._each(items, points_m, lambda kind, par, p: kind.project(p, par, self.dim))
        dist = vector_norms(rel)
        out = np.zeros_like(rel)
        out[:, 0] = 1.0
        ok = dist > 1e-12
        out[ok] = rel[ok] / dist[ok, None]
        if not ok.all() and not self.point_cores:
            for kind, sel, par in self.by_kind(items):
                low = sel[~ok[sel]]
                if low.size and not kind.point_core(self.dim):
                    out[low] = kind.escape(points_m[low], par[~ok[sel]], self.dim)[1]
        return dist, out

    def separators(self, path_m: Array, items: Array, tail: int = 0) -> tuple[Array, Array]:
        """The planner's separating half-spaces about each item's guess ``path_m`` (k, S + 1, d):
        per segment (the braking ``tail``'s hull last, :func:`mpcform.world.closest.path_closest`)
        the unit normal (k, S, d) from the core's nearest point towards the segment's, and that
        core point (k, S, d), or (k, 1, d) when every core is a point (its centre). The half-space
        ``n^T (p - anchor) >= rounding + clearance`` excludes the grown obstacle."""
        k, s1, d = path_m.shape
        if self.point_cores:
            center = self.centers_m[items][:, None]
            normal = path_closest(path_m - center, tail)  # divided in place, as the pairs' normals
            _normalise(normal)
            return normal, center
        segments = s1 - tail if tail > 1 else s1 - 1  # as path_closest: the tail's hull is one
        normal, anchor = np.empty((k, segments, d)), np.empty((k, segments, d))
        for kind, sel, par in self.by_kind(items):
            path = path_m[sel]
            if kind.point_core(self.dim):
                center = par[:, None, : self.dim]
                gap = path_closest(path - center, tail)
                core = np.broadcast_to(center, gap.shape)
            else:
                gap, core = self._path_gaps(kind, par, path, tail)
            normal[sel], anchor[sel] = gap, core
            bad = vector_norms(gap) <= DEGENERATE_M
            if bad.any() and not kind.point_core(self.dim):  # the segment touches the core
                rows = np.repeat(np.arange(sel.shape[0]), segments).reshape(-1, segments)[bad]
                escape = kind.escape(core[bad] + gap[bad], par[rows], self.dim)[1]
                idx = sel[rows], np.nonzero(bad)[1]
                normal[idx] = escape
                anchor[idx] = kind.support(escape, par[rows], self.dim)
        _normalise(normal)
        return normal, anchor

    def _path_gaps(self, kind: type[Shape], par: Array, path: Array, tail: int) -> tuple[Array, Array]:
        """The closest pairs (gap, core point) per segment of paths (k, S + 1, d) of a core that is
        not a point: golden section on each segment, alternating projections on the tail's hull."""
        k, s1, d = path.shape
        heads = s1 - 1 - (tail if tail > 1 else 0)
        rows = np.repeat(par, heads, axis=0)
        a = path[:, :heads].reshape(-1, d)
        b = path[:, 1 : heads + 1].reshape(-1, d)
        gap, core = (g.reshape(k, heads, d) for g in segment_gaps(a, b, self._projector(kind, rows)))
        if tail > 1:
            hg, hc = hull_gaps(path[:, -tail - 1 :], self._projector(kind, par))
            gap, core = (
                np.concatenate([gap, hg[:, None]], axis=1),
                np.concatenate([core, hc[:, None]], axis=1),
            )
        return gap, core

    # ---- dispatch by kind -------------------------------------------------------------------------
    def by_kind(self, items: Array) -> list[tuple[type[Shape], Array, Array]]:
        """Per kind present among ``items``: the kind, the positions among the items (s,) and their
        obstacles' parameters (s, K)."""
        out = []
        for kind, idx, par in self.groups:
            where = np.flatnonzero(np.isin(items, idx))
            if where.size:
                row = np.searchsorted(idx, items[where])
                out.append((kind, where, par[row]))
        return out

    def _projector(self, kind: type[Shape], par: Array) -> Callable[[Array], Array]:
        return lambda p: kind.project(p, par, self.dim)

    def _each(
        self,
        items: Array,
        points_m: Array,
        project: Callable[[type[Shape], Array, Array], Array],
        distance: bool = False,
    ) -> tuple[Array, Array]:
        """``points - core point`` (or its norm with ``distance``) and the core points per item."""
        core = np.empty_like(points_m)
        if self.point_cores:
            core = self.centers_m[items]
        else:
            for kind, sel, par in self.by_kind(items):
                core[sel] = project(kind, par, points_m[sel])
        rel = points_m - core
        return (vector_norms(rel) if distance else rel), core


def _normalise(normal: Array) -> None:
    """Unit vectors in place (a zero vector: the first axis, any fixed unit vector being valid)."""
    dist = vector_norms(normal)
    ok = dist > DEGENERATE_M
    normal /= np.where(ok, dist, 1.0)[..., None]
    normal[~ok] = np.eye(normal.shape[-1])[0]
