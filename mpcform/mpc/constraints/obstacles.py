"""The obstacle family of the separation rows: every drone keeps its clearance from every obstacle.

Each ``(drone, obstacle)`` item within reach gets, per segment of the drone's guess path, the
half-space ``c^T (p - a) >= rounding + clearance + margin`` of the obstacle's shape
(:meth:`mpcform.world.shapes.shape_set.ShapeSet.separators`: ``c`` from the core's nearest point
``a`` towards the segment's), at both segment ends: it excludes the grown obstacle, and the guess
meets it. A drone that starts inside its required distance gets the hard no-approach row along
the distance's gradient instead, as a close pair does (:mod:`mpcform.mpc.constraints.separation`).
The unit asks the shapes, never their geometry: a new kind of obstacle changes nothing here.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.family import SeparationFamily
from mpcform.mpc.constraints.half_spaces import ClearInputs, RowPart, SegmentTest
from mpcform.mpc.constraints.rows import row_segments
from mpcform.mpc.settings import MPCSettings
from mpcform.world.closest import vector_norms
from mpcform.world.shapes.shape_set import ShapeSet


class ObstacleSeparation(SeparationFamily):
    """Drones keep ``shapes.required_m`` (m,) [m] from the obstacles' cores (the rounding plus each
    obstacle's resolved clearance, :func:`mpcform.world.obstacles.resolve_clearances`)."""

    def __init__(
        self, shapes: ShapeSet, settings: MPCSettings, tail: int = 0, grow: Array | None = None
    ) -> None:
        self.shapes, self.required_m = shapes, shapes.required_m
        self.margin_m, self.tail = settings.margin_m, tail  # the braking tail's points
        self.segs = row_segments(settings.horizon, tail)
        self.grow = np.zeros(self.segs.shape) if grow is None else grow  # per drone and row (R,) [m]

    def rows(self, p0: Array, path: Array, items: Array, on: Array, growing: Array | None = None) -> RowPart:
        """One-drone rows of the ``(drone, obstacle)`` items (O, 2) about the guess ``path``
        (n, H + 1, d) (drone-major), grown by each drone's share ``growing`` (n,)."""
        drone, ob = items[:, 0], items[:, 1]
        required = self.required_m[ob]
        normals, anchors = self.shapes.separators(path[drone], ob, self.tail)
        coeffs = np.take(normals, self.segs, axis=1)
        dist0, c0 = self.start_normals(p0[drone], ob)
        hard = dist0 < required
        coeffs[hard, 0] = c0[hard]
        if anchors.shape[1] == 1:  # point cores: one anchor (the centre) per item
            at = np.einsum("ord,od->or", coeffs, p0[drone] - anchors[:, 0])
        else:
            at = np.einsum("ord,ord->or", coeffs, p0[drone][:, None] - np.take(anchors, self.segs, axis=1))
        lower = required[:, None] + self.margin_m - at
        if growing is not None:
            lower += growing[drone][:, None] * self.grow
        lower[hard, 0] = 0.0
        return np.column_stack([drone, -1 - ob]), coeffs, lower, on, hard

    def start_normals(self, points: Array, ob: Array) -> tuple[Array, Array]:
        """Distance (k,) of each item's point (k, d) to its obstacle's core, and the unit direction
        away from it (k, d): a hard row's normal, and the push of a drone inside its distance."""
        return self.shapes.start_normals(points, ob)

    def start_distance(self, points: Array, ob: Array) -> Array:
        """Distance (k,) of each item's point (k, d) to its obstacle's core."""
        return self.shapes.gaps(points, ob)[0]

    def doubtful(self, p0: Array, spread: Array) -> tuple[Array, Array, Array]:
        """The ``(drone, obstacle)`` items that the per-drone spread bound (see
        :meth:`Separation.clear`) leaves in doubt, and by how much they clear it (negative)."""
        gap = self.shapes.core_distances(p0) - self.required_m - spread[:, None]
        need = self.margin_m + self.grow.max()
        i, m = np.nonzero(gap < need)
        return i, m, gap[i, m] - need

    def clear_test(self, guess: Array, pos: Array, i: Array, m: Array) -> ClearInputs:
        """The items' core distance at the guess (H + 1, m), the points it is measured on, how far
        their drones' positions stray from the guess (m,), and the required distances. Point cores
        are measured relative to their centres (the distance is then the norm)."""
        g, x = np.take(guess, i, axis=1), np.take(pos, i, axis=1)
        if self.shapes.point_cores:
            center = self.shapes.centers_m[m]
            g, x = g - center, x - center
            dist = vector_norms(g)
        else:
            items = np.broadcast_to(m, g.shape[:2]).ravel()
            dist = self.shapes.gaps(g.reshape(-1, g.shape[2]), items)[0].reshape(g.shape[:2])
        return dist, g, vector_norms(x - g).max(axis=0, initial=0.0), self.required_m[m]

    def first_segment(self, p0: Array, p1: Array, items: Array) -> SegmentTest:
        """The ``items``' core distance at ``p0``, along the first segment to ``p1``, and the
        required ones."""
        i, m = items.T
        start = self.shapes.gaps(p0[i], m)[0]
        return start, self.shapes.item_segment_distances(p0[i], p1[i], m), self.required_m[m]
