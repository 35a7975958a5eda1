"""Exports: setpoint CSVs parse back to the run; polynomial pieces reproduce the planned positions."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from saved_runs import SCENARIOS, short_run, shortened

from mpcform.errors import ValidationError
from mpcform.outputs.export import (
    CRAZYFLIE_MAX_PIECES,
    POLY_HEADER,
    PROVENANCE_JSON,
    SETPOINT_COLUMNS,
    export_run,
    read_poly,
    read_setpoints,
)
from mpcform.outputs.rundata import load_run
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario

TOLERANCE_M = 0.02  # the stated tolerance: every planned sample within 2 cm of the pieces


@pytest.mark.parametrize(
    ("name", "steps"), [("swap_planar_8", 120), ("swap_spatial_12", 100), ("go_to_goal", 400)]
)
def test_pieces_reproduce_the_planned_positions(tmp_path: Path, name: str, steps: int) -> None:
    run = short_run(name, tmp_path / "run", steps=steps)
    data = load_run(tmp_path / "run")
    result = export_run(data, tmp_path / "export", tolerance_m=TOLERANCE_M)
    assert result.fit.within_tolerance and result.fit.max_error_m <= TOLERANCE_M
    p = run.simulation.positions_m
    t = run.simulation.t_s - run.simulation.t_s[0]
    for i in range(data.n):
        parts = sorted(tmp_path.glob(f"export/drone{i:03d}_poly7*.csv"))
        assert parts, "one polynomial file (or several parts) per drone"
        poly = read_poly(parts).as_float32()  # as the Crazyflie stores them
        assert abs(poly.breaks_s[-1] - t[-1]) < 1e-5
        xyz = poly.evaluate(t)[:, :3]
        planned = p[:, i] if data.dim == 3 else np.column_stack([p[:, i], np.full(t.shape, 1.0)])
        assert np.linalg.norm(xyz - planned, axis=1).max() <= TOLERANCE_M
        assert np.all(poly.evaluate(t)[:, 3] == 0.0)  # yaw


def test_poly_files_follow_the_uav_trajectories_format(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path / "run", steps=100)
    export_run(load_run(tmp_path / "run"), tmp_path / "export", altitude_m=1.5)
    path = tmp_path / "export" / "drone000_poly7.csv"
    header = path.read_text().splitlines()[0]
    assert header == ",".join(POLY_HEADER)
    assert header.startswith("Duration,x^0,x^1") and header.endswith("yaw^6,yaw^7")
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(33), ndmin=2)  # as uav_trajectory.py
    assert data.shape[1] == 33 and np.all(data[:, 0] > 0)
    assert np.allclose(data[:, 17], 1.5) and np.all(data[:, 18:25] == 0.0)  # z = altitude, constant


def test_setpoint_csv_parses_back_to_the_run(tmp_path: Path) -> None:
    run = short_run("swap_planar_8", tmp_path / "run", steps=30)
    export_run(load_run(tmp_path / "run"), tmp_path / "export", altitude_m=2.0)
    sim = run.simulation
    u = sim.commands_mps
    for i in range(8):
        path = tmp_path / "export" / f"drone{i:03d}_setpoints.csv"
        assert path.read_text().splitlines()[0] == ",".join(SETPOINT_COLUMNS)
        cols = read_setpoints(path)
        assert np.array_equal(cols["t"], sim.t_s - sim.t_s[0])
        assert np.array_equal(np.column_stack([cols["x"], cols["y"]]), sim.positions_m[:, i])
        assert np.all(cols["z"] == 2.0) and np.all(cols["vz"] == 0.0) and np.all(cols["az"] == 0.0)
        vel = np.column_stack([cols["vx"], cols["vy"]])
        # no lag or noise: the velocity at t_j is the mean of the commands before and after it
        assert np.allclose(vel[1:-1], (u[:-1, i] + u[1:, i]) / 2, atol=1e-9)
        assert np.allclose(vel[0], u[0, i]) and np.allclose(vel[-1], u[-1, i])
        acc = np.column_stack([cols["ax"], cols["ay"]])
        assert np.allclose(acc, np.gradient(vel, sim.t_s, axis=0), atol=1e-9)
        assert np.all(cols["yaw"] == 0.0)


def test_long_fits_are_split_for_the_crazyflie(tmp_path: Path) -> None:
    short_run("obstacles_planar", tmp_path / "run", steps=300)
    result = export_run(load_run(tmp_path / "run"), tmp_path / "export", tolerance_m=0.003)
    assert result.fit.polynomial.pieces > CRAZYFLIE_MAX_PIECES and result.files_per_drone >= 2
    assert any("exceed the Crazyflie's 31" in w for w in result.warnings)
    parts = sorted((tmp_path / "export").glob("drone000_poly7_part*.csv"))
    assert len(parts) == result.files_per_drone
    rows = [sum(1 for _ in csv.reader(p.open())) - 1 for p in parts]
    assert all(0 < r <= CRAZYFLIE_MAX_PIECES for r in rows) and sum(rows) == result.fit.polynomial.pieces
    # a later export with fewer pieces replaces the parts
    export_run(load_run(tmp_path / "run"), tmp_path / "export", tolerance_m=0.05)
    assert not list((tmp_path / "export").glob("drone000_poly7_part*.csv"))


def test_provenance_goes_with_the_export(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path / "run", steps=20)
    result = export_run(load_run(tmp_path / "run"), tmp_path / "export")
    record = json.loads((tmp_path / "export" / PROVENANCE_JSON).read_text())
    assert tmp_path / "export" / PROVENANCE_JSON in result.files
    for side in ("export", "run"):
        assert record[side]["seed"] == 0 and len(record[side]["scenario_sha256"]) == 64
        assert record[side]["mpcform"] and record[side]["dependencies"]["numpy"]
    assert record["tolerance_m"] == 0.02 and record["max_fit_error_m"] <= 0.02
    assert record["pieces"] == result.fit.polynomial.pieces and record["altitude_m"] == 1.0
    assert record["crazyflie_max_pieces"] == 31 and record["warnings"] == []


def test_altitude_applies_to_planar_runs_only(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path / "run", steps=10)
    with pytest.raises(ValidationError, match="altitude: applies only to planar runs"):
        export_run(load_run(tmp_path / "run"), tmp_path / "export", altitude_m=1.0)
    result = export_run(load_run(tmp_path / "run"), tmp_path / "export")
    assert any("below the floor" in w for w in result.warnings)  # the swap is centred at z = 0


def test_a_colliding_plan_is_flagged(tmp_path: Path) -> None:
    scenario = shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), 40)
    run_scenario(scenario, tmp_path, controller="tracking")  # no separation rows: they meet at the centre
    result = export_run(load_run(tmp_path), tmp_path / "export")
    assert any("closer than d_min = 0.5 m" in w and "do not fly it" in w for w in result.warnings)
