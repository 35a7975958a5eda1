"""What an obstacle shape is: a convex *core* grown by a *rounding* radius, kept ``clearance_m`` away.

Every shape is the set of points within ``rounding`` of its core, a closed convex set: a sphere is
its centre grown by its radius; a vertical cylinder (spatial) and an axis-aligned box are their own
core, rounding 0; a cylinder in the plane is a disc, its axis grown by its radius. A drone keeps
``rounding + clearance`` from the core. Everything that asks where an obstacle is (the planner's
rows, its fast path and certification, the safety measures on a path, placement at load, the
figures and the viewer) asks through two functions of the core, both exact:

- :meth:`Shape.project`: the core's point nearest to each point (the point itself inside);
- :meth:`Shape.support`: the core's point farthest along each unit normal ``n``.

The half-space ``n^T (p - support(n)) >= rounding + clearance`` excludes the grown shape for any
unit ``n`` (the separating-hyperplane form the planner linearises about its guess); where
``n = (p - project(p)) / |p - project(p)|`` it is tight at ``p``. A *point core* (``project`` and
``support`` both the centre) lets the algorithms take the closed forms they always had
(:mod:`mpcform.world.closest`).

A shape is a frozen dataclass of its parameters in SI units and its ``clearance_m`` (None: half of
``d_min`` once resolved, :func:`mpcform.world.obstacles.resolve_clearances`); its scenario keys
(:data:`Shape.keys`) are read by :mod:`mpcform.scenario.schema`, and :meth:`Shape.to_keys` /
:meth:`Shape.from_keys` are its record in a run's files. The batch kernels are class methods over
the packed parameters (:meth:`Shape.params`) of many shapes of one kind at once
(:class:`mpcform.world.shapes.shape_set.ShapeSet`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError
from mpcform.world.shapes.convex import outline


@dataclass(frozen=True)
class ShapeKey:
    """One scenario key of a shape's ``[[obstacles]]`` table (see :class:`mpcform.scenario.key_types.Key`):
    ``type`` ``vector`` (d numbers) or ``float``; ``inf``: a float that also takes ``inf``."""

    name: str
    type: str
    doc: str
    unit: str = "m"
    required: bool = False
    bound: str = ""
    inf: bool = False
    default: Any = None
    shown_default: str | None = None


CLEARANCE_KEY = ShapeKey(
    "clearance", "float", "Distance kept from the surface.", shown_default="d_min / 2", bound=">= 0"
)


class Shape(ABC):
    """An obstacle shape (module docstring). Subclasses are frozen dataclasses whose last field is
    ``clearance_m``; ``kind`` is the scenario's ``shape`` value."""

    kind: ClassVar[str]
    summary: ClassVar[str]  # what it is, in a few words (the key reference)
    keys: ClassVar[tuple[ShapeKey, ...]]
    clearance_m: float | None

    # ---- parameters, keys and records ------------------------------------------------------
    @classmethod
    @abstractmethod
    def from_keys(cls, keys: Mapping[str, Any]) -> Shape:
        """The shape of its scenario keys (``clearance`` None: unset)."""

    @abstractmethod
    def to_keys(self) -> dict[str, Any]:
        """Its scenario keys as plain numbers and lists (``shape`` first; the run's record)."""

    @abstractmethod
    def check_dim(self, dim: int, field: str) -> None:
        """Raise a :class:`ValidationError` naming ``field`` when the shape does not fit ``dim``."""

    @abstractmethod
    def params(self, dim: int) -> Array:
        """The packed parameters (K,) the batch kernels read (rounding last)."""

    # ---- batch kernels over packed parameters (k, K), one row per point --------------------------
    @classmethod
    def point_core(cls, dim: int) -> bool:
        """Whether the core is one point (its centre, ``params[:, :dim]``) in ``dim`` dimensions."""
        return False

    @classmethod
    def rounding(cls, params: Array, dim: int) -> Array:
        """The rounding radius (k,) [m]: the last parameter."""
        return params[:, -1]

    @classmethod
    @abstractmethod
    def project(cls, points: Array, params: Array, dim: int) -> Array:
        """The core's nearest point (k, d) to each point (k, d) (itself inside the core)."""

    @classmethod
    @abstractmethod
    def support(cls, normals: Array, params: Array, dim: int) -> Array:
        """A point of the core (k, d) farthest along each unit normal (k, d)."""

    @classmethod
    @abstractmethod
    def escape(cls, points: Array, params: Array, dim: int) -> tuple[Array, Array]:
        """For points (k, d) on or inside the core: how deep inside they are (k,) [m] and the unit
        direction out of it the fastest (k, d) (the outward normal of the nearest face)."""

    # ---- drawing -------------------------------------------------------------------------------
    @abstractmethod
    def core_outline(self, dim: int, axes: tuple[int, int]) -> Array:
        """Points (k, 2) whose convex hull is the core's projection onto the plane of ``axes``."""

    @abstractmethod
    def core_mesh(self, z_range_m: tuple[float, float]) -> tuple[Array, Array]:
        """The spatial core's surface as vertices (V, 3) and convex polygonal faces (F, k) (vertex
        indices, counter-clockwise seen from outside); an unbounded height is cut to ``z_range_m``."""

    # ---- what every shape answers from its kernels --------------------------------------------
    def resolved(self, d_min_m: float | None) -> Shape:
        """This shape with its clearance set: ``clearance_m`` when given, else half of ``d_min_m``
        (0 without); itself when already set."""
        if self.clearance_m is not None:
            return self
        return self.with_clearance(0.5 * (d_min_m or 0.0))

    def with_clearance(self, clearance_m: float) -> Shape:
        """The same shape kept ``clearance_m`` [m] away."""
        return replace(self, clearance_m=clearance_m)  # type: ignore[type-var]

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

    def required_core_distance_m(self, dim: int) -> float:
        """Distance [m] a drone keeps from the core: the rounding plus the resolved clearance."""
        return float(self.rounding(self.params(dim)[None], dim)[0]) + self.resolved_clearance_m

    def distance_m(self, points_m: Array) -> Array:
        """Signed distance (k,) [m] of points (k, d) to the shape's surface (negative inside)."""
        points = np.asarray(points_m, dtype=float)
        dim = points.shape[-1]
        par = np.broadcast_to(self.params(dim), (points.shape[0], self.params(dim).shape[0]))
        gap = np.linalg.norm(points - self.project(points, par, dim), axis=-1)
        depth = self.escape(points, par, dim)[0] if not self.point_core(dim) else np.zeros(len(points))
        return np.where(gap > 0.0, gap, -depth) - self.rounding(par, dim)

    def outline_m(self, dim: int, axes: tuple[int, int], grow_m: float = 0.0) -> Array:
        """The outline (k, 2), counter-clockwise, of the shape grown by ``grow_m`` [m], projected
        onto the plane of ``axes`` (a drawing's patch)."""
        rounding = float(self.rounding(self.params(dim)[None], dim)[0])
        return outline(self.core_outline(dim, axes), rounding + grow_m)

    def normal(self, points_m: Array) -> Array:
        """Unit outward normals (k, d): the gradient of :meth:`distance_m` (a point core's centre
        itself has none: the first axis)."""
        points = np.asarray(points_m, dtype=float)
        dim = points.shape[-1]
        par = np.broadcast_to(self.params(dim), (points.shape[0], self.params(dim).shape[0]))
        v = points - self.project(points, par, dim)
        norm = np.linalg.norm(v, axis=-1)
        out = np.zeros_like(points)
        out[:, 0] = 1.0
        ok = norm > 0.0
        out[ok] = v[ok] / norm[ok, None]
        if not self.point_core(dim) and not ok.all():
            out[~ok] = self.escape(points[~ok], par[~ok], dim)[1]
        return out


def clearance(value: float | None) -> float | None:
    """A clearance [m] checked (finite, >= 0), or None (unset)."""
    return None if value is None else positive("obstacles.clearance", value, allow_zero=True)
