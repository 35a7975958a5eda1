"""A static vertical cylinder (a pole: finite or unbounded height; a disc when planar).

Spatial, the cylinder is its own core (rounding 0): the points within ``radius`` of its vertical
axis through ``center`` and within half its ``height`` of the centre's height. Planar it is the
disc of ``radius`` about ``center``: its centre grown by the radius, as a :class:`Sphere` is.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError, shown
from mpcform.world.shapes.base import CLEARANCE_KEY, Shape, ShapeKey, clearance
from mpcform.world.shapes.sphere import CENTER_KEY, RADIUS_KEY

SIDES = 48  # the polygon drawn for its circle
HEIGHT_KEY = ShapeKey(
    "height",
    "float",
    "Height of a cylinder, centred on `center`'s height (spatial only; `inf`: floor to ceiling).",
    bound="> 0",
    inf=True,
    default=float("inf"),
)


@dataclass(frozen=True, eq=False)
class Cylinder(Shape):
    """A vertical cylinder of ``radius_m`` about the axis through ``center_m`` (the middle of its
    height when finite), ``height_m`` tall (inf: unbounded; planar: a disc, inf); drones keep
    ``clearance_m`` [m] from its surface."""

    center_m: Array
    radius_m: float
    height_m: float = float("inf")
    clearance_m: float | None = None

    kind: ClassVar[str] = "cylinder"
    summary: ClassVar[str] = "a vertical cylinder, finite or floor to ceiling (a disc when planar)"
    keys: ClassVar[tuple[ShapeKey, ...]] = (CENTER_KEY, RADIUS_KEY, HEIGHT_KEY, CLEARANCE_KEY)

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_m", finite_array("obstacles.center", self.center_m, (None,)))
        object.__setattr__(self, "radius_m", positive("obstacles.radius", self.radius_m))
        if not isinstance(self.height_m, int | float) or isinstance(self.height_m, bool):
            raise ValidationError(
                "obstacles.height", f"expected a number > 0 or inf, got {shown(self.height_m)}"
            )
        if not (self.height_m > 0.0):
            raise ValidationError("obstacles.height", f"expected a number > 0 or inf, got {self.height_m!r}")
        object.__setattr__(self, "height_m", float(self.height_m))
        object.__setattr__(self, "clearance_m", clearance(self.clearance_m))

    @classmethod
    def from_keys(cls, keys: Mapping[str, Any]) -> Cylinder:
        height = keys.get("height")
        return cls(
            keys["center"], keys["radius"], float("inf") if height is None else height, keys.get("clearance")
        )

    def to_keys(self) -> dict[str, Any]:
        return {
            "shape": self.kind,
            "center": self.center_m.tolist(),
            "radius": self.radius_m,
            "height": self.height_m,
            "clearance": self.clearance_m,
        }

    def check_dim(self, dim: int, field: str) -> None:
        if self.center_m.shape != (dim,):
            raise ValidationError(f"{field}.center", f"expected {dim} numbers, got {self.center_m.tolist()}")
        if dim == 2 and np.isfinite(self.height_m):
            raise ValidationError(
                f"{field}.height", f"a planar cylinder is a disc: expected no height, got {self.height_m:g}"
            )

    def params(self, dim: int) -> Array:
        if dim == 2:
            return np.concatenate([self.center_m, [self.radius_m]])
        return np.concatenate([self.center_m, [self.radius_m, 0.5 * self.height_m, 0.0]])

    @classmethod
    def point_core(cls, dim: int) -> bool:
        return dim == 2

    @classmethod
    def project(cls, points: Array, params: Array, dim: int) -> Array:
        if dim == 2:
            return np.broadcast_to(params[:, :2], points.shape).copy()
        center, radius, half = params[:, :3], params[:, 3], params[:, 4]
        radial = points[:, :2] - center[:, :2]
        r = np.linalg.norm(radial, axis=1)
        beyond = r > radius
        scale = np.divide(radius, r, out=np.ones_like(r), where=beyond)
        out = np.empty_like(points)
        out[:, :2] = np.where(beyond[:, None], center[:, :2] + radial * scale[:, None], points[:, :2])
        out[:, 2] = np.clip(points[:, 2], center[:, 2] - half, center[:, 2] + half)
        return out

    @classmethod
    def support(cls, normals: Array, params: Array, dim: int) -> Array:
        if dim == 2:
            return np.broadcast_to(params[:, :2], normals.shape).copy()
        center, radius, half = params[:, :3], params[:, 3], params[:, 4]
        flat = np.linalg.norm(normals[:, :2], axis=1)
        out = np.empty_like(normals)
        along = np.divide(radius, flat, out=np.zeros_like(flat), where=flat > 0.0)
        out[:, :2] = center[:, :2] + normals[:, :2] * along[:, None]
        up, z = normals[:, 2], center[:, 2]
        with np.errstate(invalid="ignore"):
            out[:, 2] = np.where(up > 0.0, z + half, np.where(up < 0.0, z - half, z))
        return out

    @classmethod
    def escape(cls, points: Array, params: Array, dim: int) -> tuple[Array, Array]:
        out = np.zeros(points.shape)
        if dim == 2:
            out[:, 0] = 1.0
            return np.zeros(points.shape[0]), out
        center, radius, half = params[:, :3], params[:, 3], params[:, 4]
        radial = points[:, :2] - center[:, :2]
        r = np.linalg.norm(radial, axis=1)
        side, dz = radius - r, points[:, 2] - center[:, 2]
        cap = half - np.abs(dz)
        use_side = side <= cap
        out[:, 0] = 1.0
        out[use_side & (r > 0.0), :2] = (radial / np.where(r > 0.0, r, 1.0)[:, None])[use_side & (r > 0.0)]
        out[~use_side] = 0.0
        out[~use_side, 2] = np.where(dz[~use_side] >= 0.0, 1.0, -1.0)
        return np.maximum(np.minimum(side, cap), 0.0), out

    def core_outline(self, dim: int, axes: tuple[int, int]) -> Array:
        if dim == 2:
            return self.center_m[list(axes)][None]
        if 2 not in axes:
            ang = 2.0 * np.pi * np.arange(SIDES) / SIDES
            return self.center_m[list(axes)] + self.radius_m * np.column_stack([np.cos(ang), np.sin(ang)])
        a, b = axes
        span = [self.radius_m if k != 2 else min(0.5 * self.height_m, 1e4) for k in (a, b)]
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * span
        return self.center_m[[a, b]] + corners

    def core_mesh(self, z_range_m: tuple[float, float]) -> tuple[Array, Array]:
        half = 0.5 * self.height_m
        z0 = max(self.center_m[2] - half, z_range_m[0])
        z1 = min(self.center_m[2] + half, z_range_m[1])
        ang = 2.0 * np.pi * np.arange(SIDES) / SIDES
        ring = self.center_m[:2] + self.radius_m * np.column_stack([np.cos(ang), np.sin(ang)])
        verts = np.vstack(
            [np.column_stack([ring, np.full(SIDES, z0)]), np.column_stack([ring, np.full(SIDES, z1)])]
        )
        k = np.arange(SIDES)
        sides = np.column_stack([k, (k + 1) % SIDES, SIDES + (k + 1) % SIDES, SIDES + k])
        faces = [sides.tolist(), [list(range(SIDES))[::-1]], [list(range(SIDES, 2 * SIDES))]]
        return verts, np.array(_pad([f for group in faces for f in group]), dtype=int)


def _pad(faces: list[list[int]]) -> list[list[int]]:
    """Faces of different sizes as one rectangular array: each padded with its last vertex."""
    width = max(len(f) for f in faces)
    return [f + [f[-1]] * (width - len(f)) for f in faces]
