"""Sphere: today's obstacle, a point core grown by its radius; distance and normal in closed form,
keys and the errors that name their field."""

from __future__ import annotations

import numpy as np
import pytest
from shape_truth import fd_gradient, outside

from mpcform.errors import ValidationError
from mpcform.world.shapes import Sphere, SphereObstacle, shape_from_keys


@pytest.mark.parametrize("dim", [2, 3])
def test_distance_and_normal_in_closed_form(dim: int) -> None:
    ball = Sphere(np.arange(dim, dtype=float), 0.7, clearance_m=0.2)
    pts = outside(np.random.default_rng(dim), ball.center_m, 2.0, 200)
    rel = pts - ball.center_m
    np.testing.assert_allclose(ball.distance_m(pts), np.linalg.norm(rel, axis=1) - 0.7)
    np.testing.assert_allclose(ball.normal(pts), fd_gradient(ball.distance_m, pts), atol=1e-6)
    assert Sphere.point_core(dim) and ball.required_distance_m == pytest.approx(0.9)
    assert ball.required_core_distance_m(dim) == pytest.approx(0.9)


def test_the_old_name_is_the_sphere_and_keys_round_trip() -> None:
    assert SphereObstacle is Sphere
    ball = Sphere(np.array([1.0, 2.0, 3.0]), 0.5, 0.1)
    again = shape_from_keys({k: v for k, v in ball.to_keys().items() if k != "shape"})  # the default
    assert isinstance(again, Sphere) and again.to_keys() == ball.to_keys()
    with pytest.raises(ValidationError, match="obstacles.shape"):
        shape_from_keys({"shape": "cone"})
    with pytest.raises(ValidationError, match=r"obstacles\[2\]\.center"):
        ball.check_dim(2, "obstacles[2]")
