"""Runs in memory and read back: the same trajectory, formation data and summary; clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from saved_runs import SCENARIOS, short_run, shortened

from mpcform.errors import ValidationError
from mpcform.outputs.rundata import (
    FORMATION_NPZ,
    FormationData,
    RunData,
    RunDirError,
    formation_data,
    load_run,
    write_formation_npz,
)
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario
from mpcform.world.shapes import Box, Cylinder


def test_round_trip_with_formation_data(tmp_path: Path) -> None:
    run = short_run("obstacles_planar", tmp_path, steps=10)
    data = load_run(tmp_path)
    sim, traj = run.simulation, data.trajectory
    assert np.array_equal(traj.t_s, sim.t_s) and np.array_equal(traj.positions_m, sim.positions_m)
    assert np.array_equal(traj.commands_mps, sim.commands_mps)
    assert np.array_equal(traj.reference_m, sim.reference_m)
    assert (data.n, data.dim, data.name) == (5, 2, "obstacles_planar")
    assert data.d_min_m == 0.5 and data.v_max_mps == 1.5
    assert data.label.startswith("obstacles_planar (mpc, ")
    formation = data.formation
    assert not formation.scale_is_relative and formation.scale_ref is not None
    assert np.allclose(formation.scale_ref, 1.0)
    assert [ob.kind for ob in formation.obstacles] == ["sphere", "sphere"]  # saved by kind
    assert [(ob.radius_m, ob.clearance_m) for ob in formation.obstacles] == [(1.0, 0.25), (1.0, 0.25)]
    assert np.allclose(formation.offsets_m.mean(axis=0), 0.0)


def test_an_older_runs_sphere_rows_read_as_spheres_an_unset_clearance_as_half_of_d_min(
    tmp_path: Path,
) -> None:
    """Runs saved before obstacles had kinds hold spheres as rows (centre, radius, clearance), and
    those saved before the clearance was resolved on loading NaN for an unset one."""
    run = short_run("mission_obstacle_gap", tmp_path, steps=3)
    data = load_run(tmp_path)
    d_min = data.d_min_m
    assert d_min is not None and run.simulation.t_s.shape[0] == 4
    assert [o.clearance_m for o in data.obstacles] == [0.5 * d_min] * len(data.obstacles)  # saved resolved
    rows = np.array([[*ob.center_m, ob.radius_m, np.nan] for ob in data.formation.obstacles])
    np.savez(
        tmp_path / FORMATION_NPZ,
        offsets=data.formation.offsets_m,
        scale_ref=data.formation.scale_ref,
        obstacles=rows,
    )
    old = load_run(tmp_path)
    assert [ob.clearance_m for ob in old.formation.obstacles] == [None] * len(rows)
    assert [o.clearance_m for o in old.obstacles] == [0.5 * d_min] * len(old.obstacles)
    assert [tuple(o.center_m) for o in old.obstacles] == [tuple(o.center_m) for o in data.obstacles]


def test_cylinders_and_boxes_round_trip(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path, steps=3)
    data = load_run(tmp_path)
    shapes = (Cylinder([1.0, 2.0], 0.3, clearance_m=0.1), Box([0.0, -1.0], [1.0, 0.5]))
    write_formation_npz(tmp_path, FormationData(data.formation.offsets_m, data.formation.scale_ref, shapes))
    back = load_run(tmp_path).formation.obstacles
    assert [ob.to_keys() for ob in back] == [ob.to_keys() for ob in shapes]
    with np.load(tmp_path / FORMATION_NPZ) as npz:
        npz_files = dict(npz)
    npz_files["obstacle_records"] = np.array('[{"shape": "cone"}]')
    np.savez(tmp_path / FORMATION_NPZ, **npz_files)
    with pytest.raises(RunDirError, match="formation.npz: cannot read its obstacles"):
        load_run(tmp_path)


def test_the_run_in_memory_is_the_run_read_back(tmp_path: Path) -> None:
    scenario = shortened(load_scenario(SCENARIOS / "mission_obstacle_gap.toml"), 12)
    run = run_scenario(scenario, tmp_path)
    assert run.out_dir is not None
    memory = RunData(run.simulation, formation_data(scenario, run.simulation.t_s), run.summary, run.out_dir)
    write_formation_npz(tmp_path, memory.formation)
    saved = load_run(tmp_path)
    for key in ("t_s", "positions_m", "commands_mps", "reference_m"):
        assert np.array_equal(getattr(memory.trajectory, key), getattr(saved.trajectory, key)), key
    for key in ("offsets_m", "scale_ref"):
        assert np.array_equal(getattr(memory.formation, key), getattr(saved.formation, key), equal_nan=True)
    assert [o.to_keys() for o in memory.formation.obstacles] == [
        o.to_keys() for o in saved.formation.obstacles
    ]
    assert memory.summary == saved.summary and memory.directory == saved.directory
    assert memory.label == saved.label
    limits = (scenario.limits.d_min_m, scenario.limits.v_max_mps)
    assert (memory.d_min_m, memory.v_max_mps) == (saved.d_min_m, saved.v_max_mps) == limits
    assert np.ptp(memory.formation.scale_ref) > 0  # the mission starts shrinking the formation for the gap
    assert all(o.clearance_m == 0.5 * scenario.limits.d_min_m for o in memory.formation.obstacles)  # resolved


def test_without_formation_data_the_start_shape_is_used(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path, steps=5, formation=False)
    assert not (tmp_path / FORMATION_NPZ).exists()
    data = load_run(tmp_path)
    formation, ref = data.formation, data.trajectory.reference_m
    assert formation.scale_is_relative and formation.scale_ref is None and formation.obstacles == ()
    assert np.allclose(formation.offsets_m, ref[0] - ref[0].mean(axis=0))
    with pytest.raises(ValidationError, match="formation.scale_ref: unknown"):
        write_formation_npz(tmp_path, formation)


def test_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(RunDirError, match="no such run directory"):
        load_run(tmp_path / "missing")
    with pytest.raises(RunDirError, match="trajectory.npz: missing"):
        load_run(tmp_path)
    short_run("worked_example", tmp_path, steps=5)
    (tmp_path / "summary.json").write_text("{not json")
    with pytest.raises(RunDirError, match="summary.json: cannot read it as JSON"):
        load_run(tmp_path)
    (tmp_path / "summary.json").write_text(json.dumps([1, 2]))
    with pytest.raises(RunDirError, match="expected a JSON object"):
        load_run(tmp_path)
    np.savez(tmp_path / FORMATION_NPZ, offsets=np.zeros((2, 2)), scale_ref=np.ones(6), obstacles=np.zeros(0))
    (tmp_path / "summary.json").write_text("{}")
    with pytest.raises(
        RunDirError, match=r"formation.npz: array 'offsets' has shape \(2, 2\); expected \(n, d\)"
    ):
        load_run(tmp_path)
    np.savez(
        tmp_path / "trajectory.npz",
        t=np.arange(3.0),
        p=np.zeros((3, 2, 2)),
        u=np.zeros((3, 2, 2)),
        p_ref=np.zeros((3, 2, 2)),
    )
    with pytest.raises(
        RunDirError, match=r"trajectory.npz: array 'u' has shape \(3, 2, 2\); expected \(T-1, n, d\)"
    ):
        load_run(tmp_path)
    np.savez(
        tmp_path / "trajectory.npz",
        t=np.arange(3.0),
        p=np.zeros((3, 2, 2)),
        u=np.zeros((2, 2, 2)),
        p_ref=np.zeros((3, 2, 2)),
        scale_estimates=np.ones((2, 2)),
    )
    with pytest.raises(
        RunDirError, match=r"trajectory.npz: array 'scale_estimates' has shape \(2, 2\); expected \(T, n\)"
    ):
        load_run(tmp_path)
    np.savez(tmp_path / "trajectory.npz", t=np.arange(3.0))
    with pytest.raises(RunDirError, match=r"trajectory.npz: missing arrays \['p', 'u', 'p_ref'\]"):
        load_run(tmp_path)


def test_formation_data_of_a_scenario_without_obstacles() -> None:
    scenario = load_scenario(SCENARIOS / "swap_spatial_12.toml")
    formation = formation_data(scenario, np.linspace(0.0, 1.0, 3))
    assert isinstance(formation, FormationData) and not formation.scale_is_relative
    assert formation.offsets_m.shape == (12, 3) and formation.obstacles == ()
    assert formation.scale_ref is not None and formation.scale_ref.shape == (3,)


def test_consensus_graph_and_leaders_round_trip(tmp_path: Path) -> None:
    run = short_run("consensus_ring", tmp_path / "ring", steps=4)
    saved = load_run(tmp_path / "ring")
    ring = saved.formation
    assert ring.graph_edges is not None and ring.graph_edges.shape == (8, 2) and ring.leaders == (0,)
    assert sorted(map(tuple, ring.graph_edges.tolist()))[:2] == [(0, 1), (0, 7)]
    s_hat = saved.trajectory.scale_estimates
    assert s_hat is not None and s_hat.shape == (5, 8)
    assert np.array_equal(s_hat, run.simulation.scale_estimates)
    short_run("worked_example", tmp_path / "mpc", steps=4)
    mpc = load_run(tmp_path / "mpc").formation
    assert mpc.graph_edges is None and mpc.leaders == ()
    assert load_run(tmp_path / "mpc").trajectory.scale_estimates is None
    with np.load(tmp_path / "mpc" / FORMATION_NPZ) as npz:
        assert sorted(npz.files) == ["obstacle_records", "offsets", "scale_ref"]  # unchanged without a graph


@pytest.mark.parametrize("cut", ["head", "middle"])
def test_a_truncated_or_corrupt_archive_is_one_error_naming_it(tmp_path: Path, cut: str) -> None:
    """``head -c 5000`` of the archive (no zip directory) and a zeroed second half (corrupt members)."""
    short_run("swap_planar_8", tmp_path, steps=10)
    path = tmp_path / "trajectory.npz"
    data = path.read_bytes()
    path.write_bytes(
        data[:5000] if cut == "head" else data[: len(data) // 2] + bytes(len(data) - len(data) // 2)
    )
    with pytest.raises(RunDirError, match=r"trajectory.npz: cannot read it as a numpy .npz archive"):
        load_run(tmp_path)
    from mpcform.cli.main import main

    for command in (
        ["view", str(tmp_path)],
        ["export", str(tmp_path), "--no-flight-check"],
        ["compare", str(tmp_path)],
    ):
        assert main(command) == 2, command
