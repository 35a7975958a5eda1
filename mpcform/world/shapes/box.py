"""A static axis-aligned box (a no-fly box; a rectangle when planar): its own core, rounding 0."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from mpcform._validate import Array, finite_array
from mpcform.errors import ValidationError
from mpcform.world.shapes.base import CLEARANCE_KEY, Shape, ShapeKey, clearance
from mpcform.world.shapes.sphere import CENTER_KEY

SIZE_KEY = ShapeKey("size", "vector", "Edge lengths of a box along x, y (and z).", required=True)


@dataclass(frozen=True, eq=False)
class Box(Shape):
    """An axis-aligned box of edge lengths ``size_m`` (d,) about ``center_m`` (d,); drones keep
    ``clearance_m`` [m] from its surface."""

    center_m: Array
    size_m: Array
    clearance_m: float | None = None

    kind: ClassVar[str] = "box"
    summary: ClassVar[str] = "an axis-aligned box (a rectangle when planar)"
    keys: ClassVar[tuple[ShapeKey, ...]] = (CENTER_KEY, SIZE_KEY, CLEARANCE_KEY)

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_m", finite_array("obstacles.center", self.center_m, (None,)))
        size = finite_array("obstacles.size", self.size_m, (None,))
        if np.any(size <= 0.0):
            raise ValidationError("obstacles.size", f"expected edge lengths > 0, got {size.tolist()}")
        object.__setattr__(self, "size_m", size)
        object.__setattr__(self, "clearance_m", clearance(self.clearance_m))

    @classmethod
    def from_keys(cls, keys: Mapping[str, Any]) -> Box:
        return cls(keys["center"], keys["size"], keys.get("clearance"))

    def to_keys(self) -> dict[str, Any]:
        return {
            "shape": self.kind,
            "center": self.center_m.tolist(),
            "size": self.size_m.tolist(),
            "clearance": self.clearance_m,
        }

    def check_dim(self, dim: int, field: str) -> None:
        for name, value in (("center", self.center_m), ("size", self.size_m)):
            if value.shape != (dim,):
                raise ValidationError(f"{field}.{name}", f"expected {dim} numbers, got {value.tolist()}")

    def params(self, dim: int) -> Array:
        return np.concatenate([self.center_m, 0.5 * self.size_m, [0.0]])

    @classmethod
    def project(cls, points: Array, params: Array, dim: int) -> Array:
        center, half = params[:, :dim], params[:, dim : 2 * dim]
        return np.clip(points, center - half, center + half)

    @classmethod
    def support(cls, normals: Array, params: Array, dim: int) -> Array:
        center, half = params[:, :dim], params[:, dim : 2 * dim]
        return center + half * np.sign(normals)

    @classmethod
    def escape(cls, points: Array, params: Array, dim: int) -> tuple[Array, Array]:
        center, half = params[:, :dim], params[:, dim : 2 * dim]
        offset = points - center
        depth = half - np.abs(offset)
        axis = np.argmin(depth, axis=1)
        rows = np.arange(points.shape[0])
        out = np.zeros(points.shape)
        out[rows, axis] = np.where(offset[rows, axis] >= 0.0, 1.0, -1.0)
        return np.maximum(depth[rows, axis], 0.0), out

    def core_outline(self, dim: int, axes: tuple[int, int]) -> Array:
        half = 0.5 * self.size_m[list(axes)]
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * half
        return self.center_m[list(axes)] + corners

    def core_mesh(self, z_range_m: tuple[float, float]) -> tuple[Array, Array]:
        signs = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], dtype=float)
        verts = self.center_m + 0.5 * self.size_m * signs
        faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
        return verts, np.array(faces, dtype=int)
