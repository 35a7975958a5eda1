"""Goals the MPC cannot reach are said before the run, with the drones, spheres and time."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from mpcform.scenario.load import scenario_from_dict

GAP: dict[str, Any] = {  # three drones to the far side of two spheres that close a corridor
    "version": 1,
    "name": "closed_gap",
    "dim": 2,
    "template": {"shape": "polygon", "n": 3, "radius": 0.6},
    "initial": {"centroid": [-4.0, 0.0], "rotation": 0.0},
    "reference": {"kind": "constant", "centroid": [4.0, 0.0], "rotation": 0.0},
    "limits": {"v_max": 1.5, "d_min": 0.4, "geofence_min": [-8.0, -3.0], "geofence_max": [8.0, 3.0]},
    "obstacles": [{"center": [0.0, -1.6], "radius": 1.5}, {"center": [0.0, 1.6], "radius": 1.5}],
    "controller": {"kind": "mpc", "gain": 2.0, "horizon": 10},
    "simulation": {"dt": 0.1, "duration": 20.0},
}


def changed(**tables: dict[str, Any]) -> dict[str, Any]:
    sc = copy.deepcopy(GAP)
    for name, values in tables.items():
        sc[name] = values if name == "obstacles" else sc[name] | values
    return sc


def test_a_closed_gap_names_the_drones_the_spheres_and_the_fence() -> None:
    line = scenario_from_dict(GAP).unreachable_warning()
    assert line is not None and line.startswith("reference: drone 0 (and drones 1, 2) cannot reach")
    assert "from t = 0 s" in line and "obstacles[0], obstacles[1] and the geofence" in line


def test_an_open_gap_or_a_way_around_is_not_reported() -> None:
    wide = [{"center": [0.0, -2.2], "radius": 1.5}, {"center": [0.0, 2.2], "radius": 1.5}]
    assert scenario_from_dict(changed(obstacles=wide)).unreachable_warning() is None
    around = changed(limits={"geofence_min": [-8.0, -6.0], "geofence_max": [8.0, 6.0]})
    assert scenario_from_dict(around).unreachable_warning() is None


def test_the_tracking_allowance_can_close_a_gap_the_ideal_plan_passes() -> None:
    """A passage 0.04 m wide between the keep-outs (radius 1.5 m + clearance 0.2 m): open for the
    plan without allowance, closed by the flyable plan's 0.05 m on each sphere."""
    gap = [{"center": [0.0, -1.72], "radius": 1.5}, {"center": [0.0, 1.72], "radius": 1.5}]
    plain = scenario_from_dict(changed(obstacles=gap))
    assert plain.unreachable_warning() is None
    line = plain.flyable().unreachable_warning()
    assert line is not None and "(clearance + 0.05 m)" in line


def test_a_mission_that_ends_in_a_closed_pocket_says_when() -> None:
    frames = [{"centroid": [-4.0, 2.0]}, {"centroid": [4.0, 0.0]}]
    sc = changed(reference={"kind": "mission", "keyframes": frames})
    sc["reference"].pop("centroid"), sc["reference"].pop("rotation")
    line = scenario_from_dict(sc).unreachable_warning()
    assert line is not None
    since = float(line.split("from t = ")[1].split(" s")[0])
    assert since > 1.0


@pytest.mark.parametrize("name", ["mission_obstacle_gap", "obstacles_planar"])
def test_the_bundled_scenarios_with_obstacles_are_not_reported(name: str) -> None:
    from saved_runs import SCENARIOS

    from mpcform.scenario.load import load_scenario

    assert load_scenario(SCENARIOS / f"{name}.toml").unreachable_warning() is None


def test_a_goal_just_inside_its_grown_keep_out_is_said() -> None:
    """A box whose clearance the goal keeps by 0.02 m, inside the flyable plan's 0.05 m allowance:
    the grid calls the cell free, the exact distance does not."""
    goal_x = 4.0 + 0.6  # drone 0 of the polygon (circumradius 0.6, first vertex along x)
    box = [{"shape": "box", "center": [goal_x + 0.5 + 0.2 + 0.02, 0.0], "size": [1.0, 1.0], "clearance": 0.2}]
    plain = scenario_from_dict(changed(obstacles=box))
    assert plain.unreachable_warning() is None  # outside the clearance: the ideal plan arrives
    line = plain.flyable().unreachable_warning()
    assert line is not None and line.startswith("reference: drone 0 cannot reach its goal [4.6, 0]")
    assert "0.03 m inside obstacles[0]'s keep-out" in line and "(clearance + 0.05 m)" in line
