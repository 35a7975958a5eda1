"""What an export refuses to fly: two drones closer than ``d_min``, or a drone within an obstacle's
clearance, as planned, as retimed, as flown.

:func:`separation_breaches` gives one line per breach, naming the pair, the time and the
distance: the planned flight (the run's own samples), the retimed pieces (below ``d_min`` less
twice the fit tolerance, which the pieces may each be off by) and the flight check's true
positions on the quadrotor plant (:mod:`mpcform.outputs.flight.check`). The obstacles (any
shape, :mod:`mpcform.world.shapes`) are checked the same way (:class:`ObstacleCheck`,
:func:`obstacle_breaches`) in the run's own frame: the export's positions less its offset (a
planar run's obstacles are columns through its altitude). An export with a
breach is refused unless the user overrides it (``--allow-unsafe``, recorded in ``provenance.json``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array
from mpcform.formation import geometry
from mpcform.world.obstacles import Obstacle
from mpcform.world.shapes.shape_set import ShapeSet


@dataclass(frozen=True)
class ClosestPair:
    """The closest two drones of a flight: their distance [m], when [s] and which."""

    distance_m: float
    t_s: float
    pair: tuple[int, int]

    def describe(self) -> str:
        i, j = self.pair
        return f"drones {i} and {j} {self.distance_m:.3g} m apart at t = {self.t_s:.2f} s"


def closest_pair(t_s: Array, positions_m: Array, metric: Array | None = None) -> ClosestPair | None:
    """The closest pair over the samples ``t_s`` (K,) of ``positions_m`` (K, n, d), in the downwash
    ``metric`` ``||diag(metric) (p_i - p_j)||`` when given; None for one drone."""
    if positions_m.shape[1] < 2:
        return None
    k, i, j, dist = geometry.closest_pair(positions_m if metric is None else positions_m * metric)
    return ClosestPair(dist, float(t_s[k]), (i, j))


def separation_breaches(
    d_min_m: float | None,
    tolerance_m: float,
    planned: ClosestPair | None,
    retimed: ClosestPair | None,
    flown: ClosestPair | None,
) -> list[str]:
    """One line per breach of ``d_min`` (module docstring); planned and retimed times are the
    run's and the pieces' own."""
    if d_min_m is None:
        return []
    lines = []
    if planned is not None and planned.distance_m < d_min_m:
        lines.append(f"the planned flight brings {planned.describe()} (d_min = {d_min_m:g} m): do not fly it")
    elif retimed is not None and retimed.distance_m < d_min_m - 2.0 * tolerance_m:
        lines.append(
            f"the retimed pieces bring {retimed.describe()}, closer than d_min = {d_min_m:g} m less twice "
            "the tolerance: lower --tolerance"
        )
    if flown is not None and flown.distance_m < d_min_m:
        lines.append(f"flown on the quadrotor plant, {flown.describe()}, closer than d_min = {d_min_m:g} m")
    return lines


@dataclass(frozen=True)
class ObstacleApproach:
    """A drone's deepest approach into an obstacle's clearance: how far inside it [m] (negative:
    outside by that much), when [s], which drone and which obstacle."""

    inside_m: float
    t_s: float
    drone: int
    obstacle: int

    def describe(self) -> str:
        where = "inside" if self.inside_m > 0 else "outside"
        return (
            f"drone {self.drone} {abs(self.inside_m):.3g} m {where} the clearance of "
            f"obstacles[{self.obstacle}] at t = {self.t_s:.2f} s"
        )


class ObstacleCheck:
    """A run's ``obstacles`` (clearances resolved) checked on the export's positions: those less the
    export's ``offset_m`` (3,), a planar run's (``dim`` 2) in its plane."""

    def __init__(self, obstacles: tuple[Obstacle, ...], dim: int, offset_m: Array) -> None:
        self.shapes, self.dim, self.offset_m = ShapeSet(obstacles, dim), dim, np.asarray(offset_m, float)

    def approach(self, t_s: Array, positions_m: Array) -> ObstacleApproach | None:
        """The deepest approach over the samples ``t_s`` (K,) of the export's ``positions_m``
        (K, n, 3); None without obstacles."""
        if not len(self.shapes):
            return None
        run = (positions_m - self.offset_m)[..., : self.dim]
        inside = self.shapes.required_m - self.shapes.core_distances(run)  # (K, n, m)
        k, i, m = np.unravel_index(int(np.argmax(inside)), inside.shape)
        return ObstacleApproach(float(inside[k, i, m]), float(t_s[k]), int(i), int(m))


def obstacle_breaches(
    tolerance_m: float, retimed: ObstacleApproach | None, flown: ObstacleApproach | None
) -> list[str]:
    """One line per breach of an obstacle's clearance: the retimed pieces within the clearance
    less the fit tolerance (a drone's pieces may be that far off), the flight check's true path
    within the clearance."""
    lines = []
    if retimed is not None and retimed.inside_m > tolerance_m:
        lines.append(
            f"the retimed pieces bring {retimed.describe()}, beyond the tolerance: lower --tolerance"
        )
    if flown is not None and flown.inside_m > 0.0:
        lines.append(f"flown on the quadrotor plant, {flown.describe()}")
    return lines
