"""What a mission is made of: keyframes, explicit limits per DOF group and the drones' speed budget.

A mission moves the degrees of freedom ``x = (c [m] (d), phi [rad], s, alpha)`` (centroid, turn
angle, scale, template blend) from keyframe to keyframe; the limits bound each DOF group's
velocity, acceleration and jerk. These are validated descriptions only; the moves are planned
in :mod:`mpcform.reference.moves`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError, shown
from mpcform.formation.rotation import check_rotation, rotation_matrix
from mpcform.formation.template import Template

GROUPS = ("centroid", "rotation", "scale", "blend")
"""DOF groups: centroid [m] (d DOF), rotation angle phi [rad], scale s [1], template blend alpha [1]."""
KEYFRAME_FIELDS = {"centroid": "centroid", "rotation": "rotation", "scale": "scale", "blend": "template"}
"""The keyframe field that sets each DOF group (to name it in errors)."""
DEFAULT_SPEED_FRACTION = 0.8
RISE_TIME_S = 1.0
"""Default acceleration budget: the speed budget reached in this time (``A = V / 1 s``)."""
JERK_TIME_S = 0.5
"""Default jerk budget: the acceleration budget reached in this time (``J = A / 0.5 s``)."""


@dataclass(frozen=True, eq=False)
class Keyframe:
    """One mission keyframe; ``None`` keeps the previous keyframe's value (or the start's).

    ``centroid_m`` (d,) [m]; ``rotation`` an angle [rad] (planar) or a rotation vector [rad]
    (spatial), world orientation of the body frame; ``scale`` (> 0); ``hold_s`` [s] to stay at
    the keyframe after reaching it; ``template`` switches the formation to new offsets (same n):
    drones are assigned to them optimally and blended while the move runs.
    """

    centroid_m: Array | None = None
    rotation: Array | float | None = None
    scale: float | None = None
    hold_s: float = 0.0
    template: Template | None = None

    def __post_init__(self) -> None:
        if self.centroid_m is not None:
            c = finite_array("keyframe.centroid", self.centroid_m, (None,))
            if c.shape[0] not in (2, 3):
                raise ValidationError("keyframe.centroid", f"expected 2 or 3 numbers, got {c.shape[0]}")
            c.setflags(write=False)
            object.__setattr__(self, "centroid_m", c)
        if self.rotation is not None:
            try:
                shape = np.shape(np.array(self.rotation, dtype=float))
            except (TypeError, ValueError):
                shape = ()  # finite_array names the problem
            r = finite_array("keyframe.rotation", self.rotation, shape)
            if r.shape not in ((), (3,)):
                raise ValidationError(
                    "keyframe.rotation",
                    f"expected an angle [rad] (planar) or a rotation vector of 3 numbers [rad] "
                    f"(spatial), got shape {r.shape}",
                )
            r.setflags(write=False)
            object.__setattr__(self, "rotation", r)
        if self.scale is not None:
            object.__setattr__(self, "scale", positive("keyframe.scale", self.scale))
        object.__setattr__(self, "hold_s", positive("keyframe.hold", self.hold_s, allow_zero=True))
        if self.template is not None and not isinstance(self.template, Template):
            raise ValidationError(
                "keyframe.template", f"expected a Template, got {type(self.template).__name__}"
            )


@dataclass(frozen=True)
class MissionLimits:
    """Explicit bounds per DOF group (keys of :data:`GROUPS`); a missing group is not bounded here.

    Units per group: ``centroid`` [m/s, m/s^2, m/s^3] on the norm of the centroid's velocity,
    acceleration and jerk (not per axis); ``rotation`` [rad/s, rad/s^2, rad/s^3];
    ``scale`` and ``blend`` [1/s, 1/s^2, 1/s^3].
    """

    max_velocity: Mapping[str, float] = field(default_factory=dict)
    max_acceleration: Mapping[str, float] = field(default_factory=dict)
    max_jerk: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            raw = getattr(self, name)
            if not isinstance(raw, Mapping):
                raise ValidationError(
                    f"reference.{name}", f"expected a table of DOF groups {GROUPS}, got {raw!r}"
                )
            checked: dict[str, float] = {}
            for group, value in raw.items():
                where = f"reference.{name}.{group}"
                if group not in GROUPS:
                    raise ValidationError(where, f"unknown DOF group; expected one of {', '.join(GROUPS)}")
                if isinstance(value, bool):
                    raise ValidationError(where, f"expected a finite number > 0, got {shown(value)}")
                checked[group] = positive(where, value)
            object.__setattr__(self, name, MappingProxyType(checked))

    def get(self, kind: int, group: str) -> float:
        """Bound of derivative ``kind`` (0 velocity, 1 acceleration, 2 jerk) of ``group`` (inf: none)."""
        table = (self.max_velocity, self.max_acceleration, self.max_jerk)[kind]
        return float(table.get(group, np.inf))


@dataclass(frozen=True)
class SpeedBudget:
    """Limits derived from the drones' ``v_max_mps``: every drone's reference speed stays below
    ``fraction * v_max`` by construction.

    ``acceleration_mps2`` and ``jerk_mps3`` bound the drones' along-path reference acceleration
    and jerk (defaults: the speed budget reached in :data:`RISE_TIME_S`, the acceleration budget
    in :data:`JERK_TIME_S`). :mod:`mpcform.reference.moves` explains how a move splits the budget
    between its DOFs.
    """

    v_max_mps: float
    fraction: float = DEFAULT_SPEED_FRACTION
    acceleration_mps2: float | None = None
    jerk_mps3: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "v_max_mps", positive("limits.v_max", self.v_max_mps))
        frac = positive("reference.speed_fraction", self.fraction)
        if frac > 1.0:
            raise ValidationError("reference.speed_fraction", f"expected a number in (0, 1], got {frac:g}")
        object.__setattr__(self, "fraction", frac)
        if self.acceleration_mps2 is not None:
            a = positive("reference.drone_acceleration", self.acceleration_mps2)
            object.__setattr__(self, "acceleration_mps2", a)
        if self.jerk_mps3 is not None:
            object.__setattr__(self, "jerk_mps3", positive("reference.drone_jerk", self.jerk_mps3))

    @property
    def budgets(self) -> tuple[float, float, float]:
        """Speed [m/s], acceleration [m/s^2] and jerk [m/s^3] budgets of the drones' references."""
        v = self.fraction * self.v_max_mps
        a = v / RISE_TIME_S if self.acceleration_mps2 is None else self.acceleration_mps2
        j = a / JERK_TIME_S if self.jerk_mps3 is None else self.jerk_mps3
        return v, a, j


def as_keyframe(item: Keyframe | Mapping[str, Any], k: int) -> Keyframe:
    """Keyframe ``k`` of a mission, given as a :class:`Keyframe` or a table of its fields."""
    if isinstance(item, Keyframe):
        return item
    name = f"reference.keyframes[{k}]"
    if not isinstance(item, Mapping):
        raise ValidationError(name, f"expected a Keyframe or a table of its fields, got {item!r}")
    try:
        return Keyframe(**item)
    except TypeError as exc:
        raise ValidationError(name, f"bad keyframe fields {sorted(item)}: {exc}") from None
    except ValidationError as exc:
        raise ValidationError(exc.field.replace("keyframe", name, 1), str(exc).split(": ", 1)[1]) from None


def centroid_of(centroid: Array, dim: int, field_name: str) -> Array:
    """A keyframe's centroid [m], checked against the template's dimension ``dim``."""
    if centroid.shape != (dim,):
        raise ValidationError(
            field_name,
            f"expected {dim} numbers (the template is {'planar' if dim == 2 else 'spatial'}), "
            f"got {centroid.shape[0]}",
        )
    return centroid


def rotation_of(param: Array | float, dim: int, field_name: str) -> Array:
    """The rotation matrix (d, d) of a keyframe's angle or rotation vector [rad] in dimension ``dim``."""
    shape = np.shape(param)
    if (dim == 2 and shape != ()) or (dim == 3 and shape != (3,)):
        want = "an angle [rad] (planar)" if dim == 2 else "a rotation vector of 3 numbers [rad] (spatial)"
        raise ValidationError(field_name, f"expected {want}, got shape {shape}")
    with np.errstate(all="ignore"):  # huge rotation vectors give NaN: rejected below
        rot = rotation_matrix(dim, param, field_name)
    return check_rotation(field_name, rot, dim)
