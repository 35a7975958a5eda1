"""Saved runs read back: the contract's files, the formation data, and clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from saved_runs import short_run

from mpcform.outputs.rundata import FORMATION_NPZ, RunDirError, load_run


def test_round_trip_with_formation_data(tmp_path: Path) -> None:
    run = short_run("obstacles_planar", tmp_path, steps=10)
    data = load_run(tmp_path)
    sim = run.simulation
    assert np.array_equal(data.t_s, sim.t_s) and np.array_equal(data.positions_m, sim.positions_m)
    assert np.array_equal(data.commands_mps, sim.commands_mps)
    assert np.array_equal(data.reference_m, sim.reference_m)
    assert (data.n, data.dim, data.name) == (5, 2, "obstacles_planar")
    assert data.d_min_m == 0.5 and data.v_max_mps == 1.5
    assert data.label.startswith("obstacles_planar (mpc, ")
    assert not data.scale_is_relative and data.scale_ref is not None
    assert np.allclose(data.scale_ref, 1.0)
    assert data.obstacles.shape == (2, 4)  # centre (2), radius, clearance
    assert np.allclose(data.obstacles[:, 2:], [[1.0, 0.25], [1.0, 0.25]])
    assert np.allclose(data.offsets_m.mean(axis=0), 0.0)


def test_without_formation_data_the_start_shape_is_used(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path, steps=5, formation=False)
    assert not (tmp_path / FORMATION_NPZ).exists()
    data = load_run(tmp_path)
    assert data.scale_is_relative and data.scale_ref is None and data.obstacles.shape == (0, 4)
    assert np.allclose(data.offsets_m, data.reference_m[0] - data.reference_m[0].mean(axis=0))


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
    np.savez(tmp_path / "trajectory.npz", t=np.arange(3.0))
    with pytest.raises(RunDirError, match="missing arrays"):
        load_run(tmp_path)
