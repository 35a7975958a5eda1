"""A static sphere (a disc when planar): its centre grown by its radius (a point core)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError
from mpcform.world.shapes.base import CLEARANCE_KEY, Shape, ShapeKey, clearance

CENTER_KEY = ShapeKey("center", "vector", "Centre (a cylinder: the middle of its axis).", required=True)
RADIUS_KEY = ShapeKey("radius", "float", "Radius.", required=True, bound="> 0")


@dataclass(frozen=True, eq=False)
class Sphere(Shape):
    """A sphere (a disc when planar) of ``radius_m`` at ``center_m``; drones keep ``clearance_m``
    [m] from its surface (None: unresolved, half of d_min once resolved)."""

    center_m: Array
    radius_m: float
    clearance_m: float | None = None

    kind: ClassVar[str] = "sphere"
    summary: ClassVar[str] = "a sphere (a disc when planar)"
    keys: ClassVar[tuple[ShapeKey, ...]] = (CENTER_KEY, RADIUS_KEY, CLEARANCE_KEY)

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_m", finite_array("obstacles.center", self.center_m, (None,)))
        object.__setattr__(self, "radius_m", positive("obstacles.radius", self.radius_m))
        object.__setattr__(self, "clearance_m", clearance(self.clearance_m))

    @classmethod
    def from_keys(cls, keys: Mapping[str, Any]) -> Sphere:
        return cls(keys["center"], keys["radius"], keys.get("clearance"))

    def to_keys(self) -> dict[str, Any]:
        return {
            "shape": self.kind,
            "center": self.center_m.tolist(),
            "radius": self.radius_m,
            "clearance": self.clearance_m,
        }

    def check_dim(self, dim: int, field: str) -> None:
        if self.center_m.shape != (dim,):
            raise ValidationError(f"{field}.center", f"expected {dim} numbers, got {self.center_m.tolist()}")

    @property
    def required_distance_m(self) -> float:
        """Distance [m] a drone keeps from the centre: the radius plus the resolved clearance."""
        return self.radius_m + self.resolved_clearance_m

    def params(self, dim: int) -> Array:
        return np.concatenate([self.center_m, [self.radius_m]])

    @classmethod
    def point_core(cls, dim: int) -> bool:
        return True

    @classmethod
    def project(cls, points: Array, params: Array, dim: int) -> Array:
        return np.broadcast_to(params[:, :dim], points.shape).copy()

    @classmethod
    def support(cls, normals: Array, params: Array, dim: int) -> Array:
        return np.broadcast_to(params[:, :dim], normals.shape).copy()

    @classmethod
    def escape(cls, points: Array, params: Array, dim: int) -> tuple[Array, Array]:
        out = np.zeros(points.shape)
        out[:, 0] = 1.0  # the centre itself: any direction leaves it
        return np.zeros(points.shape[0]), out

    def core_outline(self, dim: int, axes: tuple[int, int]) -> Array:
        return self.center_m[list(axes)][None]

    def core_mesh(self, z_range_m: tuple[float, float]) -> tuple[Array, Array]:
        return self.center_m[None], np.zeros((0, 3), dtype=int)


SphereObstacle = Sphere
"""The name of :class:`Sphere` before cylinders and boxes (kept for existing scripts)."""
