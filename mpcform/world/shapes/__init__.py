"""Obstacle shapes: what a shape is (:mod:`~mpcform.world.shapes.base`: a convex core grown by a
rounding radius, asked through its projection and support), the kinds (:class:`Sphere`,
:class:`Cylinder`, :class:`Box`), the closest-pair algorithms of cores that are not a point
(:mod:`~mpcform.world.shapes.convex`) and many obstacles at once
(:class:`~mpcform.world.shapes.shape_set.ShapeSet`).

A new kind is one module here (a frozen dataclass subclassing
:class:`~mpcform.world.shapes.base.Shape`) and one entry of :data:`SHAPES`: the scenario schema,
the run files, the planner, the safety measures, the figures and the viewer take it from there.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from mpcform.errors import ValidationError, shown
from mpcform.world.shapes.base import Shape
from mpcform.world.shapes.box import Box
from mpcform.world.shapes.cylinder import Cylinder
from mpcform.world.shapes.sphere import Sphere, SphereObstacle

SHAPES: dict[str, type[Shape]] = {kind.kind: kind for kind in (Sphere, Cylinder, Box)}
"""Every obstacle kind by its scenario name (``[[obstacles]] shape = ...``), the default first."""


def shape_from_keys(keys: Mapping[str, Any]) -> Shape:
    """The obstacle of a table of scenario keys (``shape`` names its kind; ``sphere`` when absent)."""
    kind = keys.get("shape") or "sphere"
    if kind not in SHAPES:
        raise ValidationError("obstacles.shape", f"expected one of {', '.join(SHAPES)}, got {shown(kind)}")
    return SHAPES[kind].from_keys(keys)


__all__ = ["SHAPES", "Box", "Cylinder", "Shape", "Sphere", "SphereObstacle", "shape_from_keys"]
