"""The world of a run in one record: the limits and the obstacles with their clearances resolved."""

from __future__ import annotations

from dataclasses import dataclass, field

from mpcform.world.limits import Limits
from mpcform.world.obstacles import Obstacle, resolve_clearances


@dataclass(frozen=True, eq=False)
class World:
    """``limits`` (:class:`~mpcform.world.limits.Limits`) and ``obstacles``; an obstacle's unset
    clearance is resolved to half of ``limits.d_min_m`` on construction
    (:func:`~mpcform.world.obstacles.resolve_clearances`), so ``obstacles`` are always resolved."""

    limits: Limits = field(default_factory=Limits)
    obstacles: tuple[Obstacle, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", resolve_clearances(tuple(self.obstacles), self.limits.d_min_m))
