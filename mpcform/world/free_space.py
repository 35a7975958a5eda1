"""Free space: where a drone can go around the obstacles and inside the geofence.

The free space of one drone (a point) is the geofence box minus every obstacle grown by its
clearance (as the planner tightens them). :class:`FreeSpace` labels
its connected regions on a grid over the box that holds the fence, the spheres and the points
asked about (at most :data:`MAX_CELLS` cells), with ``scipy.ndimage.label`` and full (8 or 26)
connectivity. The grid test is *optimistic*: a cell counts as free when its centre lies outside
every grown obstacle shrunk by half the cell's diagonal (and inside the fence grown by half a cell), so
every path through the true free space passes only through free, connected cells. Two points in
different grid regions are therefore separated in truth: a goal said to be closed off is
closed off (a gap narrower than the grid's cell may still count as open).

Other drones are not obstacles here: a goal closed off only by parked drones is not found.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from mpcform._validate import Array
from mpcform.world.obstacles import Obstacle
from mpcform.world.shapes.shape_set import ShapeSet

MAX_CELLS = 1 << 20  # the grid's size: about 1000 x 1000 planar, 100^3 spatial
PAD_CELLS = 2  # free cells around everything when there is no fence (paths around the outside)


class FreeSpace:
    """Connected free regions of a drone around ``obstacles`` (resolved clearances) inside the
    box ``lo``..``hi`` (None: no fence); ``points_m`` (m, d): the points it will be asked about
    (the grid covers them)."""

    def __init__(
        self,
        obstacles: tuple[Obstacle, ...],
        lo: Array | None,
        hi: Array | None,
        points_m: Array,
    ) -> None:
        dim = points_m.shape[1]
        shapes = ShapeSet(obstacles, dim)
        core_lo, core_hi = core_bounds(shapes)
        grown_lo, grown_hi = core_lo - shapes.required_m[:, None], core_hi + shapes.required_m[:, None]
        low = np.minimum(
            points_m.min(axis=0),
            np.where(np.isfinite(grown_lo), grown_lo, np.inf).min(axis=0, initial=np.inf),
        )
        high = np.maximum(
            points_m.max(axis=0),
            np.where(np.isfinite(grown_hi), grown_hi, -np.inf).max(axis=0, initial=-np.inf),
        )
        if lo is not None and hi is not None:
            low, high = np.maximum(np.minimum(low, hi), lo), np.minimum(np.maximum(high, lo), hi)
        size = np.maximum(high - low, 1e-9)
        self.cell_m = float((np.prod(size) / MAX_CELLS) ** (1.0 / dim))
        while np.prod(np.ceil(size / self.cell_m) + 2 * PAD_CELLS + 1) > MAX_CELLS:
            self.cell_m *= 1.05
        self.origin_m = low - PAD_CELLS * self.cell_m
        shape = tuple(int(k) for k in np.ceil(size / self.cell_m) + 2 * PAD_CELLS + 1)
        axes = [self.origin_m[a] + self.cell_m * np.arange(shape[a]) for a in range(dim)]
        half_diagonal = 0.5 * self.cell_m * np.sqrt(dim)
        free = np.ones(shape, dtype=bool)
        if lo is not None and hi is not None:
            for a, x in enumerate(axes):  # outside the fence grown by half a cell
                out = (x < lo[a] - 0.5 * self.cell_m) | (x > hi[a] + 0.5 * self.cell_m)
                free[(slice(None),) * a + (out,)] = False
        self.blocked_by = np.full(shape, -1, dtype=np.intp)  # an obstacle covering each cell
        for k, ob in enumerate(shapes.shapes):
            box = tuple(
                slice(*np.searchsorted(x, [grown_lo[k, a] + half_diagonal, grown_hi[k, a] - half_diagonal]))
                for a, x in enumerate(axes)
            )
            if any(b.start >= b.stop for b in box):
                continue
            local = np.stack(
                np.meshgrid(*[x[b] for x, b in zip(axes, box, strict=True)], indexing="ij"), axis=-1
            )
            depth = ob.distance_m(local.reshape(-1, dim)).reshape(local.shape[:-1])
            inside = depth < ob.resolved_clearance_m - half_diagonal
            self.blocked_by[box][inside] = k
            free[box] &= ~inside
        self.free = free
        self.labels = ndimage.label(free, structure=np.ones((3,) * dim, dtype=bool))[0]

    def region(self, points_m: Array) -> Array:
        """The region label (m,) of each point (0: inside an obstacle or outside the fence)."""
        return self.labels[self._cells(points_m)]

    def blocker(self, points_m: Array) -> Array:
        """The obstacle (index) each point (m, d) lies in, -1 for none."""
        return self.blocked_by[self._cells(points_m)]

    def _cells(self, points_m: Array) -> tuple[Array, ...]:
        idx = np.rint((points_m - self.origin_m) / self.cell_m).astype(np.intp)
        return tuple(np.clip(idx, 0, np.array(self.labels.shape) - 1).T)

    def walls(self, region_a: int, region_b: int) -> tuple[list[int], bool]:
        """What closes region ``a`` off from region ``b``: the obstacles (indices) that border both,
        and whether the geofence borders both."""
        grow = np.ones((3,) * self.labels.ndim, dtype=bool)
        rings = []
        for label in (region_a, region_b):
            inside = self.labels == label
            rings.append(ndimage.binary_dilation(inside, structure=grow) & ~inside)
        spheres = [set(self.blocked_by[ring].tolist()) for ring in rings]
        fence = [bool(np.any(~self.free[ring] & (self.blocked_by[ring] < 0))) for ring in rings]
        return sorted(k for k in spheres[0] & spheres[1] if k >= 0), fence[0] and fence[1]


def core_bounds(shapes: ShapeSet) -> tuple[Array, Array]:
    """The axis-aligned bounds (m, d) each of the obstacles' cores (its support along each axis;
    +-inf where a core is unbounded)."""
    d, m = shapes.dim, len(shapes)
    lo, hi = np.zeros((m, d)), np.zeros((m, d))
    for a in range(d):
        e = np.zeros((m, d))
        e[:, a] = 1.0
        for kind, sel, par in shapes.by_kind(np.arange(m)):
            hi[sel, a] = kind.support(e[sel], par, d)[:, a]
            lo[sel, a] = kind.support(-e[sel], par, d)[:, a]
    return lo, hi
