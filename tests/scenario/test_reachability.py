"""Goals the MPC cannot reach are said before the run, with the drones, spheres and time."""

from __future__ import annotations

import copy
import tomllib
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


PACE = "reference: its "


def _gap(**changes: dict[str, Any]) -> dict[str, Any]:
    from saved_runs import SCENARIOS

    data = tomllib.loads((SCENARIOS / "mission_obstacle_gap.toml").read_text())
    for table, values in changes.items():
        data[table] |= values
    return data


def test_a_reference_faster_than_a_max_is_said_once() -> None:
    """mission_obstacle_gap with ``drone_acceleration = 3`` and ``a_max = 0.4`` (issue 57: 75 %
    complete in 20 s, without a word): one line, the field, both values and the duration."""
    fast = scenario_from_dict(_gap(reference={"drone_acceleration": 3.0}, limits={"a_max": 0.4}))
    lines = [w for w in fast.warnings() if w.startswith(PACE)]
    assert len(lines) == 1, fast.warnings()
    (line,) = lines
    assert "its acceleration reaches 2.99 m/s^2" in line and "above limits.a_max = 0.4 m/s^2" in line
    assert "may not complete within its duration (20 s" in line and "speed" not in line.split(":")[1]
    assert scenario_from_dict(_gap()).pace_warning() is None  # the file itself keeps within its limits


def test_the_reference_is_read_in_chunks_that_overlap(monkeypatch: pytest.MonkeyPatch) -> None:
    """Chunks of 7 steps find what one chunk finds (each overlaps the last by one sample)."""
    from mpcform.scenario import reachability

    fast = scenario_from_dict(_gap(reference={"drone_acceleration": 3.0}, limits={"a_max": 0.4}))
    whole = fast.pace_warning()
    monkeypatch.setattr(reachability, "PACE_CHUNK", 7)
    assert whole is not None and fast.pace_warning() == whole


def test_a_reference_faster_than_v_max_is_said_when_a_drone_cannot_catch_up() -> None:
    """Sampled targets, not a key: an exponential reference whose start outruns v_max is caught up
    by a drone at v_max over a long run (not said) but not in 3 s (said, with how far behind); a
    mission derived from v_max (at most ``speed_fraction x v_max``) and a constant goal are not."""
    fast = changed(reference={"kind": "exponential", "rate": 0.3})  # 8 m at 0.3 /s: 2.4 m/s at t = 0
    assert scenario_from_dict(fast).pace_warning() is None
    fast["simulation"] = fast["simulation"] | {"duration": 3.0}
    line = scenario_from_dict(fast).pace_warning()
    assert line is not None and line.startswith("reference: its speed reaches 2.4 m/s (drone 0 at t = 0 s)")
    assert (
        "above limits.v_max = 1.5 m/s, and a drone at v_max ends" in line and "its acceleration" not in line
    )
    mission = scenario_from_dict(_gap(reference={"speed_fraction": 1.0}, limits={"v_max": 1.0}))
    assert mission.pace_warning() is None
    assert scenario_from_dict(GAP).pace_warning() is None


def test_no_bundled_scenario_is_faster_than_its_limits() -> None:
    """The exponential references start above v_max and slow down: the drones catch up."""
    from saved_runs import SCENARIOS

    from mpcform.scenario.load import load_scenario

    said = {}
    for path in sorted(SCENARIOS.glob("*.toml")):
        lines = [w for w in load_scenario(path).warnings() if w.startswith(PACE)]
        assert len(lines) <= 1, (path.name, lines)
        if lines:
            said[path.stem] = lines[0].removeprefix(PACE).split()[0]
    assert said == {}
