"""Safety measures of a sampled path (n drones, T samples, straight between samples): separation,
obstacle clearance and the geofence, at the samples and along the segments between them.

They serve the planned path (the control samples) and the plant's dense true path alike; a
required distance is met when it is missed by at most ``TOL_M``.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.formation.geometry import closest_on_segments, count_pairs_within, min_path_distance
from mpcform.world.limits import Limits
from mpcform.world.obstacles import SphereObstacle

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


def obstacle_distances_along(path_m: Array, obstacles: tuple[SphereObstacle, ...]) -> Array:
    """Smallest distance [m] of each drone's segment to each obstacle's centre, (T - 1, n, m)."""
    t, n, d = path_m.shape
    out = np.empty((t - 1, n, len(obstacles)))
    for k, ob in enumerate(obstacles):
        rel = path_m - ob.center_m
        closest = closest_on_segments(rel[:-1].reshape(-1, d), rel[1:].reshape(-1, d))
        out[..., k] = np.linalg.norm(closest, axis=1).reshape(t - 1, n)
    return out


def obstacle_metrics(path_m: Array, obstacles: tuple[SphereObstacle, ...]) -> tuple[float | None, int]:
    """``(min clearance from any obstacle's surface along the segments [m], violations)``; a violation
    is a (segment, drone, obstacle) that comes closer than its required distance, radius plus
    resolved clearance (:func:`mpcform.world.obstacles.resolve_clearances`; None, 0 without
    obstacles)."""
    if not obstacles:
        return None, 0
    dist = obstacle_distances_along(path_m, obstacles)
    radius = np.array([ob.radius_m for ob in obstacles])
    required = np.array([ob.required_distance_m for ob in obstacles])
    return float((dist - radius).min()), int((dist < required - TOL_M).sum())


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
