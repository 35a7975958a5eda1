"""What an export refuses to fly: two drones closer than ``d_min``, as planned, as retimed, as flown.

:func:`separation_breaches` gives one line per breach, naming the pair, the time and the
distance: the planned flight (the run's own samples), the retimed pieces (below ``d_min`` less
twice the fit tolerance, which the pieces may each be off by) and the flight check's true
positions on the quadrotor plant (:mod:`mpcform.outputs.flight.check`). An export with a breach
is refused unless the user overrides it (``--allow-unsafe``, recorded in ``provenance.json``).
"""

from __future__ import annotations

from dataclasses import dataclass

from mpcform._validate import Array
from mpcform.formation import geometry


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
