"""What a shape is: the answers every shape gives from its core's projection and support
(distance, normal, outline, clearance), and a kind written here, in the test, that the planner, its
certification and the safety measures take as they are: a new shape needs no change in mpc/ or sim/."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pytest
from shape_truth import fd_gradient, nearest, outside

from mpcform.errors import ValidationError
from mpcform.formation.kinematics import forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.reference.base import ConstantReference
from mpcform.sim.safety import obstacle_metrics
from mpcform.sim.simulation import simulate
from mpcform.world.limits import Limits
from mpcform.world.shapes.base import CLEARANCE_KEY, Shape, ShapeKey
from mpcform.world.shapes.sphere import Sphere


@dataclass(frozen=True, eq=False)
class Wall(Shape):
    """A planar wall: the segment ``start_m -> end_m`` grown by ``half_width_m`` (a capsule)."""

    start_m: np.ndarray
    end_m: np.ndarray
    half_width_m: float
    clearance_m: float | None = None

    kind: ClassVar[str] = "wall"
    summary: ClassVar[str] = "a capsule"
    keys: ClassVar[tuple[ShapeKey, ...]] = (CLEARANCE_KEY,)

    @classmethod
    def from_keys(cls, keys: Mapping[str, Any]) -> Wall:
        return cls(
            np.asarray(keys["start"]), np.asarray(keys["end"]), keys["half_width"], keys.get("clearance")
        )

    def to_keys(self) -> dict[str, Any]:
        return {"shape": self.kind, "start": self.start_m.tolist(), "end": self.end_m.tolist()}

    def check_dim(self, dim: int, field: str) -> None:
        if dim != 2:
            raise ValidationError(field, "a wall is planar")

    def params(self, dim: int) -> np.ndarray:
        return np.concatenate([self.start_m, self.end_m, [self.half_width_m]])

    @classmethod
    def project(cls, points: np.ndarray, params: np.ndarray, dim: int) -> np.ndarray:
        a, b = params[:, :2], params[:, 2:4]
        t = np.clip(((points - a) * (b - a)).sum(1) / ((b - a) ** 2).sum(1), 0.0, 1.0)
        return a + t[:, None] * (b - a)

    @classmethod
    def support(cls, normals: np.ndarray, params: np.ndarray, dim: int) -> np.ndarray:
        a, b = params[:, :2], params[:, 2:4]
        return np.where(((normals * a).sum(1) >= (normals * b).sum(1))[:, None], a, b)

    @classmethod
    def escape(cls, points: np.ndarray, params: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
        a, b = params[:, :2], params[:, 2:4]
        side = (b - a)[:, ::-1] * [-1.0, 1.0]
        return np.zeros(len(points)), side / np.linalg.norm(side, axis=1, keepdims=True)

    def core_outline(self, dim: int, axes: tuple[int, int]) -> np.ndarray:
        return np.stack([self.start_m, self.end_m])

    def core_mesh(self, z_range_m: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError


WALL = Wall(np.array([0.0, -0.6]), np.array([0.4, 1.2]), 0.15, clearance_m=0.2)


def test_distance_and_normal_of_a_new_kind_come_from_its_projection() -> None:
    pts = outside(np.random.default_rng(0), np.array([0.2, 0.3]), 2.0, 300)
    seg = WALL.start_m + np.linspace(0.0, 1.0, 20001)[:, None] * (WALL.end_m - WALL.start_m)
    np.testing.assert_allclose(WALL.distance_m(pts), nearest(pts, seg) - 0.15, atol=1e-4)
    away = pts[WALL.distance_m(pts) > -0.1]
    np.testing.assert_allclose(WALL.normal(away), fd_gradient(WALL.distance_m, away), atol=1e-5)
    assert WALL.required_core_distance_m(2) == pytest.approx(0.35)


def test_the_outline_is_the_grown_core() -> None:
    ring = WALL.outline_m(2, (0, 1), grow_m=0.2)
    np.testing.assert_allclose(WALL.distance_m(ring), 0.2, atol=2e-3)  # a 64-gon's chords


def test_clearance_resolves_to_half_of_d_min_once() -> None:
    unset = Sphere(np.zeros(2), 1.0)
    with pytest.raises(ValidationError, match="obstacles.clearance"):
        _ = unset.resolved_clearance_m
    assert unset.resolved(0.6).clearance_m == 0.3 and unset.resolved(None).clearance_m == 0.0
    kept = unset.with_clearance(0.1)
    assert kept.resolved(0.6) is kept


def test_the_planner_flies_a_formation_past_a_kind_it_has_never_seen() -> None:
    tpl = Template.polygon(4, 0.6)
    start = forward_kinematics(tpl, FormationState.from_param([-3.0, 0.0]))
    ref = ConstantReference(tpl, FormationState.from_param([3.0, 0.3]))
    lim = Limits(v_max_mps=1.0, d_min_m=0.4)
    planner = MPCPlanner(ref, 0.1, lim, MPCSettings(horizon=10), obstacles=(WALL,))
    res = simulate(planner, start, 16.0)
    clearance_m, violations = obstacle_metrics(res.positions_m, (WALL,))
    assert violations == 0 and clearance_m is not None and clearance_m >= 0.2 - 1e-6
    assert np.linalg.norm(res.positions_m[-1] - res.reference_m[-1], axis=1).max() < 0.05
