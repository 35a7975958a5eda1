"""Where a scenario puts its drones: apart, inside the geofence, clear of the obstacles.

Checked when a scenario is loaded, each as a :class:`~mpcform.errors.ScenarioError` naming the key:

- two template offsets (or two explicit start positions) at one point: no separation d_min > 0
  can hold between them, and a template whose offsets are all zero has no shape;
- a start (before the seeded perturbation) inside an obstacle, closer to its surface than
  its ``clearance`` (the obstacles' clearances resolved, an unset one to d_min / 2 as for
  the planner's obstacle rows: :func:`mpcform.world.obstacles.resolve_clearances`), or outside
  the geofence box;
- a constant reference whose goal puts a drone inside an obstacle or outside the geofence: it
  would hold it there;
- a start or a reference that takes a drone beyond :data:`MAX_EXTENT_M` (a scale of 1e308): the
  distances would overflow.

A moving reference (exponential, mission) may pass through obstacles: the MPC goes around them.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ScenarioError, ValidationError
from mpcform.formation.template import check_distinct as distinct_points
from mpcform.world.limits import Limits
from mpcform.world.obstacles import Obstacle

Obstacles = tuple[Obstacle, ...]
MAX_EXTENT_M = 1e6  # the farthest a drone may be from the origin (as a vector key's magnitude)


def check_distinct(points_m: Array, field: str, what: str = "offsets") -> None:
    """Raise when two rows of ``points_m`` (n, d) are at one point (or all are zero, n >= 2): the
    rule of :meth:`~mpcform.formation.template.Template.centred`
    (:func:`mpcform.formation.template.check_distinct`), as a :class:`ScenarioError`."""
    try:
        distinct_points(points_m, field, what)
    except ValidationError as exc:
        raise ScenarioError(exc.field, exc.message) from None


def check_extent(points_m: Array, field: str, what: str) -> None:
    """Raise when positions (..., d) are not finite or lie beyond :data:`MAX_EXTENT_M`."""
    far = float(np.abs(points_m).max(initial=0.0)) if np.isfinite(points_m).all() else np.inf
    if far > MAX_EXTENT_M:
        raise ScenarioError(
            field,
            f"{what} a drone {far:.3g} m from the origin; expected at most {MAX_EXTENT_M:g} m "
            "(check the scale, centroid and offsets)",
        )


def check_start(positions_m: Array, field: str, limits: Limits, obstacles: Obstacles) -> None:
    """Raise when a start position (n, d) lies inside an obstacle or outside the geofence."""
    _inside_geofence(positions_m, field, "starts", "every start", limits)
    _clear_of_obstacles(positions_m, field, "starts", obstacles)


def check_goal(goal_m: Array, field: str, limits: Limits, obstacles: Obstacles) -> None:
    """Raise when a constant reference's goal positions (n, d) put a drone inside an obstacle or
    outside the geofence: it would hold it there (or the planner would keep it short of its goal)."""
    _inside_geofence(goal_m, field, "has its constant goal", "every goal", limits)
    note = " (a moving reference, exponential or mission, may pass through obstacles)"
    _clear_of_obstacles(goal_m, field, "has its constant goal", obstacles, note)


def _inside_geofence(points_m: Array, field: str, verb: str, every: str, limits: Limits) -> None:
    lo, hi = limits.geofence_min_m, limits.geofence_max_m
    if lo is None or hi is None or lo.shape != points_m.shape[1:]:
        return
    outside = np.flatnonzero(((points_m < lo) | (points_m > hi)).any(axis=1))
    if outside.size:
        i = int(outside[0])
        raise ScenarioError(
            field,
            f"drone {i}{_more(outside)} {verb} at {_point(points_m[i])}, outside the geofence box "
            f"limits.geofence_min = {_point(lo)} to limits.geofence_max = {_point(hi)}; expected "
            f"{every} inside it",
        )


def _clear_of_obstacles(points_m: Array, field: str, verb: str, obstacles: Obstacles, note: str = "") -> None:
    for k, ob in enumerate(obstacles):
        try:
            ob.check_dim(points_m.shape[1], f"obstacles[{k}]")
        except ValidationError:
            continue  # reported elsewhere (obstacles[k].center has the wrong length)
        need = ob.resolved_clearance_m
        dist = ob.distance_m(points_m)  # to the surface, negative inside
        inside = np.flatnonzero(dist < need)
        if inside.size:
            i = int(inside[np.argmin(dist[inside])])
            where = f"{dist[i]:.4g} m from the surface of" if dist[i] >= 0 else f"{-dist[i]:.4g} m inside"
            raise ScenarioError(
                field,
                f"drone {i}{_more(inside)} {verb} at {_point(points_m[i])}, {where} obstacles[{k}] "
                f"({ob.kind}), within its clearance {need:.4g} m; expected every drone at least that "
                f"far{note}",
            )


def _more(indices: Array) -> str:
    return f" (and {indices.size - 1} more)" if indices.size > 1 else ""


def _point(p: Array) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in p) + "]"
