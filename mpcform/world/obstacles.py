"""Static obstacles (:mod:`mpcform.world.shapes`), with the clearance drones keep from them resolved once.

A scenario (or a Python user) may leave an obstacle's ``clearance_m`` unset: it then defaults to
half of ``d_min`` (0 without d_min). :func:`resolve_clearances` fills that default in where the
obstacles enter the package (the scenario's loader, :class:`mpcform.mpc.planner.MPCPlanner`,
:class:`mpcform.world.world.World`); every consumer below reads ``clearance_m`` as a float
(:class:`mpcform.world.shapes.shape_set.ShapeSet`) and never takes d_min for it.
"""

from __future__ import annotations

from collections.abc import Iterable

from mpcform.errors import ValidationError, shown
from mpcform.world.shapes import SHAPES
from mpcform.world.shapes.base import Shape

Obstacle = Shape
"""An obstacle is a shape of :data:`mpcform.world.shapes.SHAPES`."""


def obstacles_of(obstacles: Iterable[object], field: str = "obstacles") -> tuple[Shape, ...]:
    """``obstacles`` as a tuple of shapes; anything else is a :class:`ValidationError` naming it."""
    out = tuple(obstacles)
    for k, ob in enumerate(out):
        if not isinstance(ob, Shape):
            kinds = ", ".join(kind.__name__ for kind in SHAPES.values())
            raise ValidationError(f"{field}[{k}]", f"expected an obstacle shape ({kinds}), got {shown(ob)}")
    return out  # type: ignore[return-value]


def resolve_clearances(obstacles: Iterable[Shape], d_min_m: float | None) -> tuple[Shape, ...]:
    """The obstacles with every unset clearance set to half of ``d_min_m`` (0 without d_min): the
    one place the default is worked out (:meth:`~mpcform.world.shapes.base.Shape.resolved`)."""
    return tuple(o.resolved(d_min_m) for o in obstacles_of(obstacles))


def require_resolved(obstacles: Iterable[Shape]) -> tuple[Shape, ...]:
    """``obstacles`` as a tuple; raise a :class:`ValidationError` when a clearance is unset."""
    out = obstacles_of(obstacles)
    unset = [k for k, o in enumerate(out) if o.clearance_m is None]
    if unset:
        raise ValidationError(
            f"obstacles[{unset[0]}].clearance",
            "unresolved (None): resolve the default d_min / 2 first "
            "(mpcform.world.obstacles.resolve_clearances)",
        )
    return out
