"""Did the run arrive? Completion of every drone at the reference's final targets, for any controller.

A drone is complete when it ends within ``tol_m`` of its final target (the reference's value at
the end of the run: a mission's last keyframe once it is flown, a constant reference's goal, an
exponential reference's state at that time), and stalled when it ends short of it and moved less
than ``tol_m`` over the run's last ``STALL_WINDOW_S``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.sim.trajectory import Trajectory

COMPLETION_TOL_M = 0.1
STALL_WINDOW_S = 2.0


def completion_metrics(
    trajectory: Trajectory, tol_m: float = COMPLETION_TOL_M, goal_m: Array | None = None
) -> dict[str, Any]:
    """``completion`` (fraction of drones within ``tol_m`` of their final target at the end),
    ``incomplete_drones`` and ``incomplete_distances_m`` (the ids of the drones that end farther,
    and how far [m]: moving or not), ``stalled_drones`` (how many of them barely moved over the last
    ``STALL_WINDOW_S``) and ``time_to_complete`` [s] (from when on every drone stays within
    ``tol_m``; None if the run ends incomplete). Positions are the plant's: the true motion.
    ``goal_m`` (n, d): the final targets when the reference ends after the run (a mission cut
    short), else the reference at the run's end."""
    p, t = trajectory.positions_m, trajectory.t_s
    goal = trajectory.reference_m[-1] if goal_m is None else goal_m
    dist = np.linalg.norm(p - goal, axis=-1)  # (T, n)
    done = dist <= tol_m
    window = t >= t[-1] - STALL_WINDOW_S
    moved = np.linalg.norm(p[window] - p[-1], axis=-1).max(axis=0)  # (n,)
    every = done.all(axis=1)
    since = None
    if every[-1]:
        last_miss = np.flatnonzero(~every)
        since = float(t[0] if last_miss.size == 0 else t[last_miss[-1] + 1])
    missing = np.flatnonzero(~done[-1])
    return {
        "completion": float(done[-1].mean()),
        "incomplete_drones": [int(i) for i in missing],
        "incomplete_distances_m": [float(dist[-1, i]) for i in missing],
        "stalled_drones": int((~done[-1] & (moved < tol_m)).sum()),
        "time_to_complete": since,
    }
