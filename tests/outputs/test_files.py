"""Output files: exactly the contract's arrays, columns and keys, and they round-trip."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mpcform.outputs.files import (
    DEPENDENCIES,
    OUTPUT_FILES,
    SCALE_ESTIMATES,
    SUMMARY_KEYS,
    csv_header,
    format_summary,
    json_safe,
    plant_events,
    write_summary_json,
)
from mpcform.run.runner import RunResult, run_scenario
from mpcform.scenario.load import load_scenario

ROOT = Path(__file__).resolve().parents[2]
METRIC_KEYS = {
    "incomplete_drones",
    "incomplete_distances_m",
    "final_tracking_error",
    "max_tracking_error",
    "min_separation",
    "min_separation_segments",
    "max_speed",
    "separation_violations",
    "speed_violations",
    "qp_solves",
    "fast_path_steps",
    "solver_failures",
    "max_slack",
    "step_time_ms",
    # added with the plants, completion and geofence metrics (the worked example has no obstacles)
    "min_separation_true",
    "separation_violations_true",
    "max_speed_true",
    "max_tracking_error_true",
    "geofence_violations",
    "geofence_violations_true",
    "completion",
    "stalled_drones",
    "time_to_complete",
    "stall_events",
    "resolutions",
    "circling_resets",  # the planner's liveness events
    "deadline_misses",  # online planning (controller.step_budget)
    "budget_cuts",
    "slack_steps",
    "lowered_first_rows",  # the separation guarantee's conditions (braking terminal condition)
    "max_growth_slack",
    "growth_slack_steps",  # in wind: plans within their rows' growth (not slack)
    "max_wind_shift",
    "growth_exceeded_steps",  # in wind: the growth's premise, checked every step
}


def run_short(name: str, out_dir: Path, steps: int = 7) -> RunResult:
    scenario = load_scenario(ROOT / "scenarios" / f"{name}.toml")
    sim = dataclasses.replace(scenario.simulation, duration_s=steps * scenario.simulation.dt_s)
    return run_scenario(dataclasses.replace(scenario, simulation=sim), out_dir)


def strict_json(path: Path) -> Any:
    def reject(token: str) -> None:
        raise ValueError(f"non-standard JSON constant {token}")

    return json.loads(path.read_text(), parse_constant=reject)


@pytest.mark.parametrize("name", ["worked_example", "spatial_scale_rotation"])
def test_npz_holds_exactly_the_simulation(tmp_path: Path, name: str) -> None:
    run = run_short(name, tmp_path / "out")
    assert run.out_dir == tmp_path / "out"
    assert sorted(p.name for p in run.out_dir.iterdir()) == sorted(OUTPUT_FILES)
    sim = run.simulation
    with np.load(run.out_dir / "trajectory.npz") as npz:
        assert set(npz.files) == {"t", "p", "u", "p_ref", "t_true", "p_true", "v_true", "p_ref_true"}
        true = sim.true
        assert true is not None
        dense = {
            "t_true": true.t_s,
            "p_true": true.positions_m,
            "v_true": true.velocities_mps,
            "p_ref_true": true.reference_m,
        }
        for key, value in dense.items():
            assert np.array_equal(npz[key], value)
        assert np.array_equal(npz["p_true"][::10], npz["p"])  # ideal plant: the samples themselves
        assert np.array_equal(npz["t"], sim.t_s)
        assert np.array_equal(npz["p"], sim.positions_m)
        assert np.array_equal(npz["u"], sim.commands_mps)
        assert np.array_equal(npz["p_ref"], sim.reference_m)
        t_len, n, d = npz["p"].shape
        assert npz["u"].shape == (t_len - 1, n, d) and npz["p_ref"].shape == (t_len, n, d)


def test_npz_adds_the_scale_estimates_of_a_consensus_run_only(tmp_path: Path) -> None:
    run = run_short("consensus_ring", tmp_path / "out")
    s_hat = run.simulation.scale_estimates
    assert s_hat is not None
    with np.load(tmp_path / "out" / "trajectory.npz") as npz:
        assert set(npz.files) == {
            "t",
            "p",
            "u",
            "p_ref",
            "t_true",
            "p_true",
            "v_true",
            "p_ref_true",
            SCALE_ESTIMATES,
        }
        assert npz[SCALE_ESTIMATES].shape == (8, 8) and np.array_equal(npz[SCALE_ESTIMATES], s_hat)


@pytest.mark.parametrize(
    ("name", "header"),
    [
        ("worked_example", "t,drone,x,y,vx,vy,x_ref,y_ref"),
        ("go_to_goal", "t,drone,x,y,z,vx,vy,vz,x_ref,y_ref,z_ref"),
    ],
)
def test_csv_columns_and_round_trip(tmp_path: Path, name: str, header: str) -> None:
    run = run_short(name, tmp_path)
    sim = run.simulation
    t_len, n, d = sim.positions_m.shape
    lines = (tmp_path / "trajectory.csv").read_text().splitlines()
    assert lines[0] == header == ",".join(csv_header(d))
    with (tmp_path / "trajectory.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == t_len * n
    axes = "xyz"[:d]
    for k, row in enumerate(rows):
        j, i = divmod(k, n)
        assert float(row["t"]) == sim.t_s[j] and int(row["drone"]) == i
        assert [float(row[a]) for a in axes] == sim.positions_m[j, i].tolist()
        assert [float(row[f"{a}_ref"]) for a in axes] == sim.reference_m[j, i].tolist()
        commands = [row[f"v{a}"] for a in axes]
        if j < t_len - 1:
            assert [float(c) for c in commands] == sim.commands_mps[j, i].tolist()
        else:
            assert commands == [""] * d  # no command at the final time


def test_summary_keys_and_values(tmp_path: Path) -> None:
    run = run_short("worked_example", tmp_path)
    summary = strict_json(tmp_path / "summary.json")
    assert summary == run.summary
    assert tuple(summary) == (*SUMMARY_KEYS, "plant")
    assert summary["plant"]["kind"] == "ideal" and summary["plant"]["margin"] == 0.0
    assert summary["scenario"] == "worked_example"
    assert (summary["n"], summary["dim"], summary["dt"], summary["steps"]) == (3, 2, 0.02, 7)
    assert summary["controller"] == "tracking" and summary["solver"] is None
    assert summary["limits"] == {
        "v_max": 3.0,
        "d_min": 0.5,
        "tracking": 0.0,
        "downwash": None,
        "v_max_z": None,
    }
    assert set(summary["metrics"]) == METRIC_KEYS
    prov = summary["provenance"]
    assert set(prov["dependencies"]) == set(DEPENDENCIES)
    assert prov["seed"] == 0 and len(prov["scenario_sha256"]) == 64
    assert prov["mpcform"] and prov["python"]
    assert "final tracking error" in format_summary(summary)
    assert "growth buffer" not in format_summary(summary) and "wind" not in format_summary(summary)
    summary["metrics"] |= {"growth_slack_steps": 3, "max_growth_slack": 0.012}
    summary["metrics"] |= {"max_wind_shift": 0.011, "growth_exceeded_steps": 2}
    lines = format_summary(summary).splitlines()
    used = next(r for r in lines if r.startswith("growth buffer used"))
    assert used.endswith(" 3 steps, at most 0.012 m (required distances kept)")
    shift = next(r for r in lines if r.startswith("wind shift"))
    assert shift.endswith(" at most 0.011 m per step, above the growth on 2 steps")


def test_unset_and_infinite_values_are_null(tmp_path: Path) -> None:
    run = run_short("go_to_goal", tmp_path)  # one drone: no separation; no d_min
    summary = strict_json(tmp_path / "summary.json")
    assert summary["limits"] == {
        "v_max": 2.0,
        "d_min": None,
        "tracking": 0.0,
        "downwash": None,
        "v_max_z": None,
    }
    assert summary["metrics"]["min_separation"] is None
    assert run.summary["metrics"]["min_separation_segments"] is None
    assert "-" in format_summary(summary)


def test_json_safe_replaces_nan_and_inf(tmp_path: Path) -> None:
    value = {"a": float("nan"), "b": [np.float64(np.inf), 1.5, np.int64(3)], "c": (None, "x")}
    assert json_safe(value) == {"a": None, "b": [None, 1.5, 3], "c": [None, "x"]}
    write_summary_json(tmp_path / "s.json", value)
    assert strict_json(tmp_path / "s.json")["b"] == [None, 1.5, 3]


def test_plant_events_are_one_line_or_none() -> None:
    assert plant_events({"kind": "lag"}) is None
    assert plant_events({"drone_contacts": [], "floor_contacts": [], "flipped": []}) is None
    line = plant_events(
        {"drone_contacts": [[0, 3]], "floor_contacts": [0, 2], "planning_stopped_s": {"0": 0.6, "2": 1.25}}
    )
    said = (
        "drone contacts: [0, 3]; on the floor: 0, 2; planning stopped for drone 0 at 0.6 s, drone 2 at 1.25 s"
    )
    assert line == said


def test_the_printed_summary_reports_true_geofence_and_obstacle_violations(tmp_path: Path) -> None:
    """A plant's dense motion's geofence and obstacle violations are printed beside its separation
    and speed ones, and its obstacle clearance beside the plan's: the figures of summary.json."""
    run_short("worked_example", tmp_path)
    summary = strict_json(tmp_path / "summary.json")
    summary["plant"] |= {"kind": "crazyflow", "margin": 0.05}
    summary["metrics"] |= {"geofence_violations": 0, "geofence_violations_true": 2167}
    summary["metrics"] |= {"obstacle_violations": 0, "min_obstacle_clearance": 0.21}
    summary["metrics"] |= {"obstacle_violations_true": 4, "min_obstacle_clearance_true": -0.012}
    lines = format_summary(summary).splitlines()
    assert next(r for r in lines if r.startswith("violations")).endswith(
        " 0 separation, 0 speed, 0 obstacle, 0 geofence"
    )
    true = next(r for r in lines if r.startswith("true motion"))
    assert ", violations 0 separation, 4 obstacle, 2167 geofence, max speed " in true
    obstacles = next(r for r in lines if r.startswith("obstacles"))
    assert obstacles.endswith(" 0.21 m from a surface (true motion -0.012 m), 0 violations")
    summary["plant"]["kind"] = "ideal"  # its dense motion is the plan's path: one clearance
    obstacles = next(r for r in format_summary(summary).splitlines() if r.startswith("obstacles"))
    assert obstacles.endswith(" 0.21 m from a surface, 0 violations")
