"""Safety measures of a sampled path (n drones, T samples, straight between samples): separation,
obstacle clearance and the geofence, at the samples and along the segments between them.

They serve the planned path (the control samples) and the plant's dense true path alike; a
required distance is met when it is missed by at most ``TOL_M``.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.formation.geometry import count_pairs_within, min_path_distance
from mpcform.world.limits import Limits
from mpcform.world.obstacles import Obstacle
from mpcform.world.shapes.shape_set import ShapeSet

TOL_M = 1e-9
"""A distance short of its requirement by at most this much [m] is not a violation."""


def min_separation_along(path_m: Array, metric: Array | None = None) -> float:
    """Smallest distance between two drones along the straight segments of ``path_m`` (T, n, d) [m]
    (in the scaled coordinates ``metric * p`` when given, e.g. the downwash ellipsoid's)."""
    p = path_m if metric is None else path_m * metric
    return min_path_distance(p)


def separation_violations(path_m: Array, d_min_m: float, metric: Array | None = None) -> int:
    """Number of (sample, pair) closer than ``d_min_m - TOL_M``."""
    p = path_m if metric is None else path_m * metric
    return count_pairs_within(p, d_min_m - TOL_M)


def obstacle_distances_along(path_m: Array, obstacles: tuple[Obstacle, ...]) -> Array:
    """Smallest distance [m] of each drone's segment to each obstacle's core, (T - 1, n, m) (a
    sphere's: its centre; :mod:`mpcform.world.shapes`)."""
    t, n, d = path_m.shape
    shapes = ShapeSet(obstacles, d)
    dist = shapes.segment_distances(path_m[:-1].reshape(-1, d), path_m[1:].reshape(-1, d))
    return dist.reshape(t - 1, n, len(shapes))


def obstacle_metrics(path_m: Array, obstacles: tuple[Obstacle, ...]) -> tuple[float | None, int]:
    """``(min clearance from any obstacle's surface along the segments [m], violations)``; a violation
    is a (segment, drone, obstacle) that comes closer than its clearance to the surface (its
    resolved clearance, :func:`mpcform.world.obstacles.resolve_clearances`; None, 0 without
    obstacles)."""
    if not obstacles:
        return None, 0
    dist = obstacle_distances_along(path_m, obstacles)
    shapes = ShapeSet(obstacles, path_m.shape[2])
    return float((dist - shapes.rounding_m).min()), int((dist < shapes.required_m - TOL_M).sum())


def geofence_violations(path_m: Array, limits: Limits) -> int:
    """Number of (sample, drone) outside the geofence box (the box is convex, so a straight segment
    leaves it only if one of its ends does); 0 without a geofence."""
    if limits.geofence_min_m is None or limits.geofence_max_m is None:
        return 0
    low = path_m < limits.geofence_min_m - TOL_M
    high = path_m > limits.geofence_max_m + TOL_M
    return int((low | high).any(axis=-1).sum())


def downwash_metric(limits: Limits, dim: int) -> Array | None:
    """The scaling ``diag(1, 1, 1 / kappa)`` of the downwash ellipsoid (None without downwash)."""
    if limits.downwash_kappa is None or dim != 3:
        return None
    return np.array([1.0, 1.0, 1.0 / limits.downwash_kappa])
