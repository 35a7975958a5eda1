"""The obstacles as the viewer's page draws them (:mod:`mpcform.outputs.viewer`), any kind alike.

A point core (a sphere, a planar cylinder) is a centre, a radius and a clearance: the page shades
it as a ball. Any other shape is drawn from its geometry (:mod:`mpcform.world.shapes`): planar,
its outline and the outline grown by its clearance (dashed); spatial, its surface as convex faces,
an unbounded height cut to the flight's heights. A new kind of obstacle needs nothing here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError, shown
from mpcform.world.obstacles import Obstacle, obstacles_of, resolve_clearances

DECIMALS = 4  # [m]: 0.1 mm


def obstacle_payload(
    obstacles: tuple[Obstacle, ...] | None, dim: int, d_min_m: float | None, points_m: Array
) -> list[dict[str, Any]]:
    """The page's record of each obstacle (clearances resolved with ``d_min_m``), spatial surfaces
    cut to the heights of ``points_m`` (..., d) with some room."""
    shapes = resolve_clearances(obstacles_of(obstacles or ()), d_min_m)
    z = points_m.reshape(-1, dim)[:, -1]
    room = 0.5 * float(np.ptp(z)) + 0.5 if z.size else 1.0
    z_range = (float(z.min(initial=0.0)) - room, float(z.max(initial=0.0)) + room)
    out = []
    for k, ob in enumerate(shapes):
        ob.check_dim(dim, f"obstacles[{k}]")
        par = ob.params(dim)[None]
        record: dict[str, Any] = {"kind": ob.kind, "clear": _r(ob.resolved_clearance_m)}
        if ob.point_core(dim):
            record |= {"c": [_r(x) for x in par[0, :dim]], "r": _r(float(ob.rounding(par, dim)[0]))}
        elif dim == 2:
            record["outline"] = _points(ob.outline_m(dim, (0, 1)))
            record["grown"] = _points(ob.outline_m(dim, (0, 1), ob.resolved_clearance_m))
        else:
            verts, faces = ob.core_mesh(z_range)
            if not np.all(np.isfinite(verts)):
                raise ValidationError(
                    f"obstacles[{k}]", f"expected a finite surface, got {shown(verts.tolist())}"
                )
            record["mesh"] = {"v": _points(verts), "f": faces.astype(int).tolist()}
        out.append(record)
    return out


def _points(points: Array) -> list[list[float]]:
    return [[_r(x) for x in p] for p in points]


def _r(x: float) -> float:
    return round(float(x), DECIMALS)
