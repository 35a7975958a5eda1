"""Goals the MPC cannot reach, said before a run: closed off by spheres and the geofence.

With the planner's own tightening (:func:`mpcform.world.limits.tightened`: radius + clearance +
twice the plant's margin + the tracking allowance), each drone's final target must lie in the
same free region as its start (:class:`mpcform.world.free_space.FreeSpace`, a grid flood fill
that never calls a passable gap closed). A target that lies in another region is reported with
the drones, the spheres (and the fence) that close it off, and the time from which the reference
keeps it there. A reference that passes through a sphere on its way is not reported: the MPC goes
around it, and only where it ends matters.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mpcform.world.free_space import FreeSpace
from mpcform.world.limits import tightened

if TYPE_CHECKING:
    from mpcform.scenario.spec import Scenario

TIMES = 200  # reference samples searched for the time a target becomes unreachable


def unreachable_warning(scenario: Scenario) -> str | None:
    """One line naming the drones whose final targets the MPC cannot reach, or None."""
    if not scenario.obstacles:
        return None
    rob = scenario.robustness
    limits, obstacles = tightened(scenario.limits, scenario.obstacles, rob.margin_m, rob.a_max_mps2)
    end = max(scenario.simulation.duration_s, getattr(scenario.reference, "duration_s", 0.0) or 0.0)
    times = np.linspace(0.0, end, TIMES + 1)
    targets = scenario.reference.targets(times)[0]  # (T, n, d)
    start = scenario.initial_positions_m
    points = np.concatenate([start, targets.reshape(-1, start.shape[1])])
    space = FreeSpace(obstacles, limits.geofence_min_m, limits.geofence_max_m, points)
    home = space.region(start)
    region = space.region(targets.reshape(-1, start.shape[1])).reshape(targets.shape[:2])
    cut = (region[-1] != home) & (home > 0)
    if not cut.any():
        return None
    drones = np.flatnonzero(cut)
    i = int(drones[0])
    reached = np.flatnonzero(region[:, i] == home[i])
    since = times[reached[-1] + 1] if reached.size else 0.0
    spheres, fence = space.walls(int(home[i]), int(region[-1, i])) if region[-1, i] > 0 else ([], False)
    what = [f"obstacles[{k}]" for k in spheres] + ["the geofence"] * fence
    inside = int(space.blocker(targets[-1, i : i + 1])[0])
    where = (
        f"inside obstacles[{inside}]'s keep-out"
        if region[-1, i] == 0 and inside >= 0
        else "outside the geofence"
        if region[-1, i] == 0
        else f"closed off from its start by {_listed(what) or 'the spheres'}"
    )
    more = f" (and drones {', '.join(map(str, drones[1:].tolist()))})" if drones.size > 1 else ""
    return (
        f"reference: drone {i}{more} cannot reach its goal {_point(targets[-1, i])}: from t = {since:.3g} s "
        f"its target lies {where}, with the planner's tightening (radius + clearance + "
        f"{2.0 * rob.margin_m + scenario.limits.tracking_m:.3g} m); the run will end incomplete "
        "(move the goal, the spheres or the fence)"
    )


def _listed(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1] if names else ""


def _point(p: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.3g}" for x in p) + "]"
