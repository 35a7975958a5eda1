"""What a planner derives from the user's limits once, where it is built: its planning bounds.

A plan is flown by a plant that may be off it by a *tube* (tube MPC with a constant tightening):
the planner keeps ``d_min + 2 tube`` between two drones (each may be off by the tube; in the
downwash metric too, which only shrinks lengths), ``clearance + 2 tube`` from every obstacle and
the geofence shrunk by ``2 tube`` (the plan starts from a measured position up to a tube off the
previous plan, and the next interval adds up to another: a static obstacle, unlike a pair, has no
second drone to share it). The tracking allowance ``e = limits.tracking_m`` is added once more,
for the flown drone off the planned path: ``d_min + 2 (tube + e)``, ``clearance + 2 tube + e``,
the fence shrunk by ``2 tube + e``. ``a_max`` unset takes the plant's bound, else the platform's
:data:`~mpcform.world.limits.DEFAULT_A_MAX_MPS2`; ``a_max = inf`` plans without one. In wind the
rows also grow along the horizon by ``growth_m`` per interval (:mod:`mpcform.mpc.constraints.rows`).

:func:`planning_bounds` is the one place this is worked out; its errors name the keys the user
wrote (``plant.margin``, ``plant.margin_growth``), never a derived one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError, shown
from mpcform.world.limits import DEFAULT_A_MAX_MPS2, Limits
from mpcform.world.obstacles import Obstacle, require_resolved


@dataclass(frozen=True, eq=False)
class PlanningBounds:
    """The bounds a planner keeps, derived from the user's ``limits`` (:func:`planning_bounds`):
    ``v_max_mps``, ``v_max_z_mps`` [m/s] and ``downwash_kappa`` as given; ``d_min_m`` [m] and the
    geofence ``geofence_min_m``, ``geofence_max_m`` (d,) [m] tightened by the tube; ``a_max_mps2``
    [m/s^2] resolved (None: no bound); ``tube_m`` [m] the plant's margin and the tracking allowance
    they are tightened by; ``growth_m`` [m] the rows' growth per interval in wind."""

    limits: Limits
    v_max_mps: float | None
    d_min_m: float | None
    a_max_mps2: float | None
    geofence_min_m: Array | None
    geofence_max_m: Array | None
    downwash_kappa: float | None
    v_max_z_mps: float | None
    tube_m: float = 0.0
    growth_m: float = 0.0

    @classmethod
    def of(cls, limits: Limits, tube_m: float = 0.0, growth_m: float = 0.0) -> PlanningBounds:
        """The bounds exactly as ``limits`` state them (``a_max`` as given, nothing tightened), kept
        for a plant within ``tube_m`` [m] and a growth of ``growth_m`` [m]: what a caller that has
        derived its own bounds hands the planner's parts."""
        tube = positive("plant.margin", tube_m, allow_zero=True)
        growth = positive("plant.margin_growth", growth_m, allow_zero=True)
        a_max = None if limits.a_max_mps2 is None or not np.isfinite(limits.a_max_mps2) else limits.a_max_mps2
        return cls(
            limits,
            limits.v_max_mps,
            limits.d_min_m,
            a_max,
            limits.geofence_min_m,
            limits.geofence_max_m,
            limits.downwash_kappa,
            limits.v_max_z_mps,
            tube,
            growth,
        )

    def speed_scale(self, dim: int) -> Array:
        """Per-axis factors (d,) that map the velocity set's spheroid onto the ball of radius
        ``v_max`` (:meth:`mpcform.world.limits.Limits.speed_scale`)."""
        return self.limits.speed_scale(dim)


def planning_bounds(
    limits: Limits,
    obstacles: tuple[Obstacle, ...] = (),
    tube_m: float = 0.0,
    a_max_mps2: float | None = None,
    growth_m: float = 0.0,
) -> tuple[PlanningBounds, tuple[Obstacle, ...]]:
    """The bounds and obstacles a planner keeps (module docstring) for a plant within ``tube_m``
    [m] of every planned segment, whose margin assumes command changes within ``a_max_mps2``
    (taken where the limits set none), in a wind whose reach per interval is ``growth_m`` [m]. The
    obstacles' clearances must be resolved (:func:`mpcform.world.obstacles.resolve_clearances`)."""
    if not isinstance(limits, Limits):
        raise ValidationError("limits", f"expected mpcform.Limits, got {shown(limits)}")
    obstacles = require_resolved(obstacles)
    tube = positive("plant.margin", tube_m, allow_zero=True)
    growth = positive("plant.margin_growth", growth_m, allow_zero=True)
    e = limits.tracking_m
    a_max = limits.a_max_mps2 if limits.a_max_mps2 is not None else a_max_mps2
    if a_max is None:
        a_max = DEFAULT_A_MAX_MPS2
    elif not np.isfinite(a_max):
        a_max = None  # inf: no bound
    lo, hi, d_min = limits.geofence_min_m, limits.geofence_max_m, limits.d_min_m
    static = 2.0 * tube + e  # a fence or an obstacle: the plant's tube twice, the tracking once
    bounds = PlanningBounds(
        limits,
        limits.v_max_mps,
        None if d_min is None else d_min + 2.0 * (tube + e),
        a_max,
        None if lo is None else lo + static,
        None if hi is None else hi - static,
        limits.downwash_kappa,
        limits.v_max_z_mps,
        tube + e,
        growth,
    )
    return bounds, tuple(o.with_clearance(o.resolved_clearance_m + static) for o in obstacles)
