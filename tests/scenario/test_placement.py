"""Where a scenario puts its drones: distinct offsets and starts, starts inside the geofence and clear of
obstacles, a constant goal clear of obstacles (a moving reference may cross them)."""

from __future__ import annotations

import tomllib
from typing import Any

import numpy as np
import pytest
from saved_runs import SCENARIOS

from mpcform.errors import ScenarioError
from mpcform.scenario.load import scenario_from_dict
from mpcform.scenario.placement import check_distinct, check_extent, check_goal, check_start
from mpcform.world.limits import Limits
from mpcform.world.obstacles import resolve_clearances
from mpcform.world.shapes import SphereObstacle


def obstacles_doc(**changes: Any) -> dict[str, Any]:
    """obstacles_planar.toml (a pentagon of radius 1.5 m at x = -8; discs at (0, +-1.8), radius 1,
    clearance 0.25; d_min 0.5; geofence |y| <= 4) with ``{"table.key": value}`` changes."""
    data = tomllib.loads((SCENARIOS / "obstacles_planar.toml").read_text())
    for dotted, value in changes.items():
        table, key = dotted.rsplit(".", 1)
        node = data[table] if "[" not in table else data["obstacles"][int(table[-2])]
        if value is None:
            node.pop(key, None)
        else:
            node[key] = value
    return data


def error(data: dict[str, Any]) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data)
    return info.value


# ---- starts ----------------------------------------------------------------------------------
def test_a_start_inside_an_obstacle_names_the_start_key_drone_and_obstacle() -> None:
    exc = error(obstacles_doc(**{"initial.centroid": [0.0, 1.0]}))  # drone 1 at (0.46, 2.43)
    assert exc.field == "initial.centroid"
    assert "obstacles[0] (sphere), within its clearance 0.25 m" in str(exc)


def test_the_clearance_defaults_to_half_of_d_min() -> None:
    lim, ob = Limits(d_min_m=0.5), SphereObstacle(np.zeros(2), 1.0)
    resolved = resolve_clearances((ob,), lim.d_min_m)
    assert resolved[0].required_distance_m == 1.25
    check_start(np.array([[1.25, 0.0]]), "initial.positions", lim, resolved)  # on the boundary: fine
    with pytest.raises(
        ScenarioError,
        match=r"0.24 m from the surface of obstacles\[0\] \(sphere\), within its clearance 0.25 m",
    ):
        check_start(np.array([[1.24, 0.0]]), "initial.positions", lim, resolved)
    no_d_min = resolve_clearances((ob,), None)
    check_start(np.array([[1.01, 0.0]]), "initial.positions", Limits(), no_d_min)  # radius only


def test_a_start_outside_the_geofence() -> None:
    exc = error(obstacles_doc(**{"initial.centroid": [-8.0, 3.5]}))
    assert exc.field == "initial.centroid" and "outside the geofence box" in str(exc)
    assert "(and 1 more)" in str(exc)  # two drones above y = 4


def test_explicit_start_positions_are_checked_under_their_own_key() -> None:
    positions = [[-8.0 + 1.5 * np.cos(a), 1.5 * np.sin(a)] for a in 2 * np.pi * np.arange(5) / 5]
    positions[2] = [0.0, 1.8]  # at an obstacle's centre
    data = obstacles_doc(**{"initial.centroid": None})
    data["initial"]["positions"] = positions
    exc = error(data)
    assert exc.field == "initial.positions" and "drone 2 starts at [0, 1.8]" in str(exc)


def test_duplicate_start_positions() -> None:
    data = obstacles_doc(**{"initial.centroid": None})
    data["initial"]["positions"] = [[-8.0, 0.0], [-7.0, 0.0], [-8.0, 0.0], [-9.0, 1.0], [-9.0, -1.0]]
    exc = error(data)
    assert exc.field == "initial.positions" and "start positions 0 and 2 coincide" in str(exc)


def test_the_check_uses_the_start_before_the_seeded_perturbation() -> None:
    scenario_from_dict(obstacles_doc(**{"initial.perturbation": 5.0}))  # perturbed starts may not be clear


# ---- goals -----------------------------------------------------------------------------------
def test_a_constant_goal_inside_an_obstacle() -> None:
    data = obstacles_doc(
        **{"reference.kind": "constant", "reference.rate": None, "reference.centroid": [0.0, 0.3]}
    )
    exc = error(data)
    assert exc.field == "reference.centroid" and "constant goal" in str(exc)
    assert "a moving reference, exponential or mission, may pass through obstacles" in str(exc)


def test_a_constant_goal_without_a_centroid_names_the_reference_table() -> None:
    data = obstacles_doc(**{"reference.kind": "constant", "reference.rate": None, "reference.centroid": None})
    scenario_from_dict(data)  # the goal is the start, which is clear
    goal = scenario_from_dict(data).reference.start_positions_m()
    with pytest.raises(ScenarioError) as info:
        check_goal(goal, "reference", Limits(), resolve_clearances((SphereObstacle(goal[0], 0.1),), 0.5))
    assert info.value.field == "reference" and "drone 0" in str(info.value)


def test_a_constant_goal_outside_the_geofence() -> None:
    """It would be held there, or kept short of it by the fence rows; a start there is refused too."""
    goal = np.array([[0.0, 0.0], [5.0, 0.0]])
    fence = Limits(geofence_min_m=np.array([-1.0, -1.0]), geofence_max_m=np.array([4.0, 1.0]))
    with pytest.raises(ScenarioError) as info:
        check_goal(goal, "reference.centroid", fence, ())
    assert "drone 1 has its constant goal at [5, 0], outside the geofence box" in str(info.value)
    check_goal(goal, "reference.centroid", Limits(), ())  # no fence


def test_a_moving_reference_may_pass_through_an_obstacle() -> None:
    data = obstacles_doc(**{"reference.centroid": [0.0, 0.3]})  # exponential towards the same goal
    assert scenario_from_dict(data).n == 5


# ---- templates -------------------------------------------------------------------------------
def test_coincident_and_zero_offsets() -> None:
    with pytest.raises(ScenarioError, match=r"offsets 0 and 2 coincide at \[1, 0\]"):
        check_distinct(np.array([[1.0, 0.0], [-2.0, 0.0], [1.0, 0.0]]), "template.offsets")
    with pytest.raises(ScenarioError, match="all 3 offsets are zero"):
        check_distinct(np.zeros((3, 2)), "template.offsets")
    check_distinct(np.zeros((1, 3)), "template.offsets")  # one drone at its centroid: fine
    check_distinct(np.array([[1e-6, 0.0], [-1e-6, 0.0]]), "template.offsets")  # close, not coincident


def test_an_explicit_template_with_coincident_offsets_is_refused() -> None:
    data = tomllib.loads((SCENARIOS / "go_to_goal.toml").read_text())
    data["template"]["offsets"] = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-2.0, 0.0, 0.0]]
    exc = error(data)
    assert exc.field == "template.offsets" and "no separation d_min > 0 can hold" in str(exc)


def test_a_degenerate_generated_template_names_its_size_key() -> None:
    data = obstacles_doc(**{"template.radius": 1e-300})
    assert error(data).field == "template.radius"


def test_a_keyframe_template_switch_is_checked_too() -> None:
    data = tomllib.loads((SCENARIOS / "mission_template_switch.toml").read_text())
    frame = next(k for k in data["reference"]["keyframes"] if "template" in k)
    index = data["reference"]["keyframes"].index(frame)
    frame["template"] = {"shape": "explicit", "offsets": [[0.0, 0.0]] * 6}
    exc = error(data)
    assert exc.field == f"reference.keyframes[{index}].template.offsets"
    assert "all 6 offsets are zero" in str(exc)


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")), ids=lambda p: p.stem)
def test_bundled_scenarios_place_their_drones_well(path: Any) -> None:
    s = scenario_from_dict(tomllib.loads(path.read_text()))
    check_distinct(s.initial_positions_m, "initial.positions", "start positions")


def test_a_start_or_reference_beyond_the_extent_names_its_table() -> None:
    """A scale of 1e308 took the drones to inf: a ValueError from cKDTree in the memory estimate."""
    data = tomllib.loads((SCENARIOS / "swap_spatial_20.toml").read_text())
    data["reference"]["scale"] = 1e308
    with pytest.raises(ScenarioError, match=r"^reference: the reference takes a drone inf m from the origin"):
        scenario_from_dict(data)
    with pytest.raises(ScenarioError, match=r"^initial: the start puts a drone 2e\+06 m"):
        check_extent(np.array([[0.0, 2e6]]), "initial", "the start puts")
    check_extent(np.array([[0.0, 1e6]]), "initial", "the start puts")
