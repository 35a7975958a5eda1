"""Goals the MPC cannot reach, said before a run: closed off by spheres and the geofence.

With the planner's own tightening (:func:`mpcform.world.bounds.planning_bounds`: radius + clearance +
twice the plant's margin + the tracking allowance), each drone's final target must lie in the
same free region as its start (:class:`mpcform.world.free_space.FreeSpace`, a grid flood fill
that never calls a passable gap closed). A target that lies in another region is reported with
the drones, the spheres (and the fence) that close it off, and the time from which the reference
keeps it there. A reference that passes through a sphere on its way is not reported: the MPC goes
around it, and only where it ends matters.

A reference faster than the limits (:func:`pace_warning`) is said too: its targets sampled at every
control step of the run, whatever the reference's kind. Speed: a drone at ``v_max`` (the velocity
set's spheroid with ``v_max_z``) along its target's path falls behind by ``lag_{k+1} = max(0,
lag_k + dt (|v*_k| - v_max))``; a reference that starts fast and slows (an exponential approach)
is caught up, one that ends more than the completion radius ahead is said. Acceleration, when
``limits.a_max`` is set: a component of the target velocities' finite differences above it (the
planner's rows bound each component's change by ``a_max dt``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mpcform._validate import Array
from mpcform.sim.completion import COMPLETION_TOL_M
from mpcform.world.bounds import planning_bounds
from mpcform.world.free_space import FreeSpace
from mpcform.world.limits import Limits
from mpcform.world.obstacles import Obstacle
from mpcform.world.shapes.shape_set import ShapeSet

TIMES = 200  # reference samples searched for the time a target becomes unreachable
PACE_RTOL = 1e-6
"""A reference's speed or acceleration exceeds a limit when above it by this fraction (rounding)."""
PACE_CHUNK = 1024
"""Steps of the reference sampled at once (its targets are (T, n, d): bounded memory at load)."""
AXES = "xyz"


def unreachable_warning(
    limits: Limits,
    obstacles: tuple[Obstacle, ...],
    tube_m: float,
    a_max_mps2: float | None,
    start_m: Array,
    times_s: Array,
    targets_m: Array,
) -> str | None:
    """One line naming the drones whose final targets the MPC cannot reach, or None: ``start_m``
    (n, d) the starts, ``targets_m`` (T, n, d) the reference's targets at ``times_s`` (T,), the
    last at the end; the limits and (resolved) obstacles tightened by the plant's ``tube_m``."""
    if not obstacles:
        return None
    planned, inflated = planning_bounds(limits, obstacles, tube_m, a_max_mps2)
    held = _held_inside(inflated, times_s, targets_m)
    if held is not None:
        return held + _tightening(limits, tube_m)
    points = np.concatenate([start_m, targets_m.reshape(-1, start_m.shape[1])])
    space = FreeSpace(inflated, planned.geofence_min_m, planned.geofence_max_m, points)
    home = space.region(start_m)
    region = space.region(targets_m.reshape(-1, start_m.shape[1])).reshape(targets_m.shape[:2])
    cut = (region[-1] != home) & (home > 0)
    if not cut.any():
        return None
    drones = np.flatnonzero(cut)
    i = int(drones[0])
    reached = np.flatnonzero(region[:, i] == home[i])
    since = times_s[reached[-1] + 1] if reached.size else times_s[0]
    walls, fence = space.walls(int(home[i]), int(region[-1, i])) if region[-1, i] > 0 else ([], False)
    what = [f"obstacles[{k}]" for k in walls] + ["the geofence"] * fence
    inside = int(space.blocker(targets_m[-1, i : i + 1])[0])
    where = (
        f"inside obstacles[{inside}]'s keep-out"
        if region[-1, i] == 0 and inside >= 0
        else "outside the geofence"
        if region[-1, i] == 0
        else f"closed off from its start by {_listed(what) or 'the obstacles'}"
    )
    more = f" (and drones {', '.join(map(str, drones[1:].tolist()))})" if drones.size > 1 else ""
    return (
        f"reference: drone {i}{more} cannot reach its goal {_point(targets_m[-1, i])}: from t = "
        f"{since:.3g} s its target lies {where}" + _tightening(limits, tube_m)
    )


def pace_warning(
    limits: Limits,
    a_max_mps2: float | None,
    dt_s: float,
    steps: int,
    velocities: Callable[[Array], Array],
    a_max_field: str,
) -> str | None:
    """One line when the reference is faster than the limits, or None: ``velocities(times_s)``
    (T, n, d) its target velocities, read at ``t = k dt_s`` for k = 0..steps (the run's steps) in
    chunks of :data:`PACE_CHUNK`; ``a_max_mps2`` the planner's bound (None: none), named
    ``a_max_field`` in the line (module docstring)."""
    speed = (0.0, 0, 0.0)  # the fastest (value, drone, time)
    lag: Array | None = None  # each drone's distance behind its target at v_max [m] (module docstring)
    acc = (0.0, 0, 0, 0.0)  # the largest component change per second (value, drone, axis, time)
    scale = None
    for first in range(0, steps + 1, PACE_CHUNK):
        k = np.arange(max(first - 1, 0), min(first + PACE_CHUNK, steps + 1))  # one sample of overlap
        t_s = dt_s * k
        v = velocities(t_s)
        if scale is None:
            scale = limits.speed_scale(v.shape[-1])
        norm = np.linalg.norm(v * scale, axis=-1)  # (T, n): v_max on the spheroid's ball
        if limits.v_max_mps is not None:
            lag = np.zeros(norm.shape[1]) if lag is None else lag
            for row in norm[:-1]:  # each interval k from its start (the chunks overlap by one sample)
                lag = np.maximum(0.0, lag + dt_s * (row - limits.v_max_mps))
        j, i = np.unravel_index(int(np.argmax(norm)), norm.shape)
        if norm[j, i] > speed[0]:
            speed = (float(norm[j, i]), int(i), float(t_s[j]))
        if v.shape[0] > 1:
            change = np.abs(np.diff(v, axis=0)) / dt_s  # (T - 1, n, d)
            j, i, axis = np.unravel_index(int(np.argmax(change)), change.shape)
            if change[j, i, axis] > acc[0]:
                acc = (float(change[j, i, axis]), int(i), int(axis), float(t_s[j]))
    parts = []
    v_max = limits.v_max_mps
    behind = 0.0 if lag is None else float(lag.max(initial=0.0))
    if v_max is not None and speed[0] > v_max * (1.0 + PACE_RTOL) and behind > COMPLETION_TOL_M:
        squeezed = " (v_max_z on the vertical)" if scale is not None and np.any(scale != 1.0) else ""
        parts.append(
            f"its speed reaches {speed[0]:.3g} m/s (drone {speed[1]} at t = {speed[2]:.3g} s), above "
            f"limits.v_max = {v_max:g} m/s{squeezed}, and a drone at v_max ends {behind:.3g} m behind"
        )
    if a_max_mps2 is not None and acc[0] > a_max_mps2 * (1.0 + PACE_RTOL):
        parts.append(
            f"its acceleration reaches {acc[0]:.3g} m/s^2 (drone {acc[1]} along {AXES[acc[2]]} at "
            f"t = {acc[3]:.3g} s), above {a_max_field}"
        )
    if not parts:
        return None
    return (
        f"reference: {' and '.join(parts)}: the drones cannot keep up with it and the run may not "
        f"complete within its duration ({steps * dt_s:.3g} s; slow the reference, e.g. a mission's "
        "speed_fraction or drone_acceleration, raise the limits or lengthen simulation.duration)"
    )


def _held_inside(inflated: tuple[Obstacle, ...], times_s: Array, targets_m: Array) -> str | None:
    """The start of the line for drones whose final target lies inside a shape grown by the
    planner's tightening, measured exactly (the grid of :class:`FreeSpace` calls a cell closed only
    when it is): a goal a few millimetres inside its keep-out can never be reached either."""
    shapes = ShapeSet(inflated, targets_m.shape[-1])
    depth = shapes.required_m - shapes.core_distances(targets_m)  # (T, n, m) > 0: inside
    inside = depth.max(axis=-1) > 0.0
    drones = np.flatnonzero(inside[-1])
    if not drones.size:
        return None
    i = int(drones[0])
    free = np.flatnonzero(~inside[:, i])
    since = times_s[0] if not free.size else times_s[free[-1] + 1]
    k = int(np.argmax(depth[-1, i]))
    more = f" (and drones {', '.join(map(str, drones[1:].tolist()))})" if drones.size > 1 else ""
    return (
        f"reference: drone {i}{more} cannot reach its goal {_point(targets_m[-1, i])}: from t = "
        f"{since:.3g} s its target lies {depth[-1, i, k]:.3g} m inside obstacles[{k}]'s keep-out"
    )


def _tightening(limits: Limits, tube_m: float) -> str:
    return (
        f", with the planner's tightening (clearance + {2.0 * tube_m + limits.tracking_m:.3g} m); the run "
        "will end incomplete (move the goal, the obstacles or the fence)"
    )


def _listed(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1] if names else ""


def _point(p: Array) -> str:
    return "[" + ", ".join(f"{x:.3g}" for x in p) + "]"
