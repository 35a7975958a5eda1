"""What an export refuses: the closest pair named with its time, and one line per breach."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.outputs.flight.check import FlightCheck
from mpcform.outputs.flight.safety import (
    ClosestPair,
    ObstacleApproach,
    ObstacleCheck,
    closest_pair,
    obstacle_breaches,
    separation_breaches,
)
from mpcform.world.shapes import Box, Cylinder


def test_closest_pair_names_the_pair_and_the_time() -> None:
    t = np.array([0.0, 0.5, 1.0])
    p = np.zeros((3, 3, 3))
    p[:, 1, 0] = [2.0, 0.4, 2.0]  # drone 1 comes to 0.4 m of drone 0 at t = 0.5 s
    p[:, 2, 1] = 5.0
    found = closest_pair(t, p)
    assert found == ClosestPair(0.4, 0.5, (0, 1))
    assert found.describe() == "drones 0 and 1 0.4 m apart at t = 0.50 s"
    assert closest_pair(t, p[:, :1]) is None


def test_one_line_per_breach() -> None:
    near, far = ClosestPair(0.3, 2.0, (1, 4)), ClosestPair(0.6, 1.0, (0, 2))
    assert separation_breaches(0.5, 0.01, far, far, far) == []
    assert separation_breaches(None, 0.01, near, near, near) == []
    planned = separation_breaches(0.5, 0.01, near, near, None)
    assert planned == [
        "the planned flight brings drones 1 and 4 0.3 m apart at t = 2.00 s (d_min = 0.5 m): do not fly it"
    ]
    retimed = separation_breaches(0.5, 0.01, far, ClosestPair(0.47, 3.0, (2, 3)), near)
    assert len(retimed) == 2 and "lower --tolerance" in retimed[0] and "quadrotor plant" in retimed[1]
    assert separation_breaches(0.5, 0.02, far, ClosestPair(0.47, 3.0, (2, 3)), None) == []  # within 2 tol


def test_a_flight_check_below_d_min_is_not_within_tolerance() -> None:
    ok = FlightCheck(0.01, 0, 1.0, 0.02, 0.01, ClosestPair(0.55, 2.0, (0, 1)), 0.5)
    assert ok.within_tolerance and ok.record()["closest_pair"] == [0, 1]
    close = FlightCheck(0.01, 0, 1.0, 0.02, 0.01, ClosestPair(0.455, 2.0, (0, 1)), 0.5)
    assert not close.within_tolerance and close.record()["within_tolerance"] is False


def test_obstacle_check_finds_the_deepest_approach_in_the_runs_frame() -> None:
    """A pole at (1, 0) of radius 0.2 with clearance 0.1 (required 0.3 from its axis): drone 1
    passes 0.25 m from the axis at t = 1 s, in an export shifted by (5, 5, 1)."""
    pole = Cylinder(np.array([1.0, 0.0]), 0.2, clearance_m=0.1)
    offset = np.array([5.0, 5.0, 1.0])
    t = np.array([0.0, 1.0, 2.0])
    p = np.zeros((3, 2, 3)) + offset
    p[:, 0, 1] += 3.0  # drone 0 stays 3 m away
    p[:, 1, 0] += [0.0, 1.25, 3.0]
    found = ObstacleCheck((pole,), 2, offset).approach(t, p)
    assert found == ObstacleApproach(pytest.approx(0.05), 1.0, 1, 0)
    assert found.describe() == "drone 1 0.05 m inside the clearance of obstacles[0] at t = 1.00 s"
    assert ObstacleCheck((), 2, offset).approach(t, p) is None


def test_a_box_is_checked_on_its_surface_in_space() -> None:
    box = Box(np.array([0.0, 0.0, 1.0]), np.array([1.0, 1.0, 2.0]), clearance_m=0.2)
    p = np.array([[[0.0, 0.0, 2.1]], [[0.65, 0.0, 1.0]]])  # 0.1 m above its top, 0.15 m off a side
    found = ObstacleCheck((box,), 3, np.zeros(3)).approach(np.array([0.0, 1.0]), p)
    assert found is not None and found.inside_m == pytest.approx(0.1) and found.t_s == 0.0


def test_one_line_per_obstacle_breach() -> None:
    deep, shallow = ObstacleApproach(0.05, 1.0, 1, 0), ObstacleApproach(0.005, 1.0, 1, 0)
    clear = ObstacleApproach(-0.2, 1.0, 1, 0)
    assert obstacle_breaches(0.01, shallow, clear) == []  # the pieces within their fit tolerance
    lines = obstacle_breaches(0.01, deep, shallow)
    assert len(lines) == 2 and "lower --tolerance" in lines[0] and "quadrotor plant" in lines[1]
    assert obstacle_breaches(0.01, None, None) == []


def test_a_flight_check_inside_an_obstacle_is_not_within_tolerance() -> None:
    inside = FlightCheck(0.01, 0, 1.0, 0.02, 0.01, obstacle=ObstacleApproach(0.02, 1.5, 3, 2))
    assert not inside.within_tolerance and "obstacles[2]" in inside.describe()
    assert inside.record()["obstacle_inside_m"] == 0.02
    outside = FlightCheck(0.01, 0, 1.0, 0.02, 0.01, obstacle=ObstacleApproach(-0.1, 1.5, 3, 2))
    assert outside.within_tolerance
