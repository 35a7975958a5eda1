"""The scenario library covers the mission, documents every file, and every file runs end to end."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from saved_runs import SCENARIOS, shortened

from mpcform.outputs.flight.export import export_run
from mpcform.outputs.rundata import formation_data, load_run, write_formation_npz
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario

FILES = sorted(SCENARIOS.glob("*.toml"))
STEPS = 6

# what the mission asks of the library -> files that show it (at least one must exist)
MISSION = {
    "worked example": ["worked_example"],
    "go-to-goal": ["go_to_goal"],
    "spatial rotation + scaling": ["spatial_scale_rotation"],
    "ruckig mission": ["worked_example_ruckig", "mission_spatial"],
    "antipodal swap, planar": ["swap_planar_8"],
    "antipodal swap, spatial": ["swap_spatial_12", "swap_spatial_20"],
    "squeeze through a gap by shrinking": ["mission_obstacle_gap"],
    "consensus ring": ["consensus_ring"],
    "null-space repulsion": ["spatial_nullspace_repulsion"],
    "obstacles": ["obstacles_planar", "mission_obstacle_gap"],
    "poles and no-fly boxes": ["poles_box_planar", "poles_box_spatial"],
    "100-drone formation flight": ["formation_flight_100"],
}


@pytest.mark.parametrize("item", sorted(MISSION))
def test_the_library_covers_the_mission(item: str) -> None:
    names = {p.stem for p in FILES}
    assert names & set(MISSION[item]), f"no scenario for {item!r} (expected one of {MISSION[item]})"


def test_every_scenario_is_documented_in_one_line() -> None:
    readme = (SCENARIOS / "README.md").read_text()
    documented = re.findall(r"^- `([\w.-]+\.toml)`: \S.*$", readme, flags=re.MULTILINE)
    assert sorted(documented) == sorted(p.name for p in FILES)


def test_the_100_drone_flight_has_100_drones() -> None:
    scenario = load_scenario(SCENARIOS / "formation_flight_100.toml")
    assert scenario.n == 100 and scenario.controller.kind == "mpc"
    assert scenario.controller.mpc.coupling == "decoupled"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_every_scenario_runs_writes_and_exports(tmp_path: Path, path: Path) -> None:
    scenario = shortened(load_scenario(path), STEPS)
    mpc = scenario.controller.kind == "mpc"
    scenario = scenario.flyable() if mpc else scenario  # export refuses a plan without the allowance
    run = run_scenario(scenario, tmp_path)
    write_formation_npz(tmp_path, formation_data(scenario, run.simulation.t_s))
    data = load_run(tmp_path)
    assert data.trajectory.positions_m.shape == (STEPS + 1, scenario.n, scenario.dim)
    assert np.all(np.isfinite(data.trajectory.positions_m)) and not data.formation.scale_is_relative
    lift = (0.0, 0.0, max(0.0, 0.5 - float(data.trajectory.positions_m[..., 2:].min(initial=0.5))))
    out = tmp_path / "export"
    opts = dict(tolerance_m=0.05, offset_m=lift, allow_limits=True, fly=False, allow_untracked=not mpc)
    result = export_run(data, out, **opts)
    assert result.fit.within_tolerance
    mission = [p for p in (tmp_path / "export").glob("drone*_setpoints.csv") if p.stem.count("_") == 1]
    assert len(mission) == scenario.n  # and the ascent's and descent's beside them
