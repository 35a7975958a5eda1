"""Free space: where a drone can go around the spheres and inside the geofence.

The free space of one drone (a point) is the geofence box minus every sphere inflated to its
required distance (radius plus clearance, as the planner tightens them). :class:`FreeSpace` labels
its connected regions on a grid over the box that holds the fence, the spheres and the points
asked about (at most :data:`MAX_CELLS` cells), with ``scipy.ndimage.label`` and full (8 or 26)
connectivity. The grid test is *optimistic*: a cell counts as free when its centre lies outside
every sphere shrunk by half the cell's diagonal (and inside the fence grown by half a cell), so
every path through the true free space passes only through free, connected cells. Two points in
different grid regions are therefore separated in truth: a goal said to be closed off is
closed off (a gap narrower than the grid's cell may still count as open).

Other drones are not obstacles here: a goal closed off only by parked drones is not found.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from mpcform._validate import Array
from mpcform.world.obstacles import SphereObstacle, obstacle_arrays

MAX_CELLS = 1 << 20  # the grid's size: about 1000 x 1000 planar, 100^3 spatial
PAD_CELLS = 2  # free cells around everything when there is no fence (paths around the outside)


class FreeSpace:
    """Connected free regions of a drone around ``obstacles`` (resolved clearances) inside the
    box ``lo``..``hi`` (None: no fence); ``points_m`` (m, d): the points it will be asked about
    (the grid covers them)."""

    def __init__(
        self,
        obstacles: tuple[SphereObstacle, ...],
        lo: Array | None,
        hi: Array | None,
        points_m: Array,
    ) -> None:
        dim = points_m.shape[1]
        centers, required = obstacle_arrays(obstacles)
        centers = centers.reshape(-1, dim)
        extent = np.concatenate([points_m, centers - required[:, None], centers + required[:, None]])
        low, high = extent.min(axis=0), extent.max(axis=0)
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
        self.blocked_by = np.full(shape, -1, dtype=np.intp)  # a sphere covering each cell
        for k, (c, r) in enumerate(zip(centers, required - half_diagonal, strict=True)):
            if r <= 0.0:
                continue
            box = tuple(self._span(x, c[a], r) for a, x in enumerate(axes))
            local = np.meshgrid(*[x[b] for x, b in zip(axes, box, strict=True)], indexing="ij")
            inside = sum((g - c[a]) ** 2 for a, g in enumerate(local)) < r * r
            self.blocked_by[box][inside] = k
            free[box] &= ~inside
        self.free = free
        self.labels = ndimage.label(free, structure=np.ones((3,) * dim, dtype=bool))[0]

    def _span(self, axis_m: Array, center_m: float, radius_m: float) -> slice:
        """The cells of one axis within ``radius_m`` of ``center_m``."""
        return slice(*np.searchsorted(axis_m, [center_m - radius_m, center_m + radius_m]))

    def region(self, points_m: Array) -> Array:
        """The region label (m,) of each point (0: inside a sphere or outside the fence)."""
        return self.labels[self._cells(points_m)]

    def blocker(self, points_m: Array) -> Array:
        """The sphere (index) each point (m, d) lies in, -1 for none."""
        return self.blocked_by[self._cells(points_m)]

    def _cells(self, points_m: Array) -> tuple[Array, ...]:
        idx = np.rint((points_m - self.origin_m) / self.cell_m).astype(np.intp)
        return tuple(np.clip(idx, 0, np.array(self.labels.shape) - 1).T)

    def walls(self, region_a: int, region_b: int) -> tuple[list[int], bool]:
        """What closes region ``a`` off from region ``b``: the spheres (indices) that border both,
        and whether the geofence borders both."""
        grow = np.ones((3,) * self.labels.ndim, dtype=bool)
        rings = []
        for label in (region_a, region_b):
            inside = self.labels == label
            rings.append(ndimage.binary_dilation(inside, structure=grow) & ~inside)
        spheres = [set(self.blocked_by[ring].tolist()) for ring in rings]
        fence = [bool(np.any(~self.free[ring] & (self.blocked_by[ring] < 0))) for ring in rings]
        return sorted(k for k in spheres[0] & spheres[1] if k >= 0), fence[0] and fence[1]
