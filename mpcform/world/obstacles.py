"""Static sphere obstacles, with the clearance drones keep from them resolved once.

A scenario (or a Python user) may leave an obstacle's ``clearance_m`` unset: it then defaults to
half of ``d_min`` (0 without d_min). :func:`resolve_clearances` fills that default in where the
obstacles enter the package (the scenario's loader, :class:`mpcform.mpc.planner.MPCPlanner`,
:class:`mpcform.world.world.World`); every consumer below reads ``clearance_m`` as a float
(:attr:`SphereObstacle.required_distance_m`, :func:`obstacle_arrays`) and never takes d_min for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError


@dataclass(frozen=True, eq=False)
class SphereObstacle:
    """A static sphere (a disc when planar) of ``radius_m`` at ``center_m``; drones keep
    ``clearance_m`` [m] from its surface (None: unresolved, half of d_min once resolved by
    :meth:`resolved` / :func:`resolve_clearances`)."""

    center_m: Array
    radius_m: float
    clearance_m: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_m", finite_array("obstacles.center", self.center_m, (None,)))
        object.__setattr__(self, "radius_m", positive("obstacles.radius", self.radius_m))
        if self.clearance_m is not None:
            object.__setattr__(
                self,
                "clearance_m",
                positive("obstacles.clearance", self.clearance_m, allow_zero=True),
            )

    def resolved(self, d_min_m: float | None) -> SphereObstacle:
        """This obstacle with its clearance set: ``clearance_m`` when given, else half of
        ``d_min_m`` (0 without); itself when already set."""
        if self.clearance_m is not None:
            return self
        return SphereObstacle(self.center_m, self.radius_m, 0.5 * (d_min_m or 0.0))

    @property
    def resolved_clearance_m(self) -> float:
        """``clearance_m`` [m]; a :class:`ValidationError` when it is unset (unresolved)."""
        if self.clearance_m is None:
            raise ValidationError(
                "obstacles.clearance",
                "unresolved (None): resolve the default d_min / 2 first "
                "(mpcform.world.obstacles.resolve_clearances)",
            )
        return self.clearance_m

    @property
    def required_distance_m(self) -> float:
        """Distance [m] a drone keeps from the centre: the radius plus the resolved clearance."""
        return self.radius_m + self.resolved_clearance_m


def resolve_clearances(
    obstacles: tuple[SphereObstacle, ...], d_min_m: float | None
) -> tuple[SphereObstacle, ...]:
    """The obstacles with every unset clearance set to half of ``d_min_m`` (0 without d_min): the
    one place the default is worked out (:meth:`SphereObstacle.resolved`)."""
    return tuple(o.resolved(d_min_m) for o in obstacles)


def require_resolved(obstacles: tuple[SphereObstacle, ...]) -> tuple[SphereObstacle, ...]:
    """``obstacles`` as a tuple; raise a :class:`ValidationError` when a clearance is unset."""
    obstacles = tuple(obstacles)
    unset = [k for k, o in enumerate(obstacles) if o.clearance_m is None]
    if unset:
        raise ValidationError(
            f"obstacles[{unset[0]}].clearance",
            "unresolved (None): resolve the default d_min / 2 first "
            "(mpcform.world.obstacles.resolve_clearances)",
        )
    return obstacles


def obstacle_arrays(obstacles: tuple[SphereObstacle, ...]) -> tuple[Array, Array]:
    """Centres (m, d) [m] and the distance (m,) [m] drones keep from each centre: the radius plus
    the resolved clearance."""
    center = np.array([o.center_m for o in obstacles])
    required = np.array([o.required_distance_m for o in obstacles])
    return center, required
