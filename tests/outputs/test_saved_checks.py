"""A saved run read back is checked first: sizes before reading, then shapes and finite values,
each refusal one RunDirError naming the file and the array or field."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest
from saved_runs import short_run

from mpcform.outputs.rundata import FORMATION_NPZ, load_run
from mpcform.outputs.saved_checks import MAX_NPZ_BYTES, MAX_SUMMARY_BYTES, RunDirError


@pytest.fixture(scope="module")
def saved(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short saved run with formation.npz (obstacles), read-only by convention: copy it first."""
    out = tmp_path_factory.mktemp("saved") / "run"
    short_run("obstacles_planar", out, steps=5)
    return out


def _copy(saved: Path, tmp_path: Path) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    for f in saved.iterdir():
        (run / f.name).write_bytes(f.read_bytes())
    return run


def _rewrite(path: Path, **changes: object) -> None:
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update(changes)
    np.savez(path, **{k: v for k, v in arrays.items() if v is not None})


def _array(path: Path, key: str) -> np.ndarray:
    with np.load(path) as npz:
        return np.array(npz[key])


@pytest.mark.parametrize("key", ["t", "p", "u", "p_ref", "p_true"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_value_names_the_file_and_the_array(
    saved: Path, tmp_path: Path, key: str, bad: float
) -> None:
    run = _copy(saved, tmp_path)
    npz = run / "trajectory.npz"
    if key not in np.load(npz).files:
        pytest.skip(f"{key} not saved by this run")
    value = _array(npz, key)
    value.reshape(-1)[1] = bad
    _rewrite(npz, **{key: value})
    with pytest.raises(
        RunDirError, match=rf"trajectory.npz: array '{key}' holds {bad} at index .*expected finite"
    ):
        load_run(run)


def test_shapes_and_times(saved: Path, tmp_path: Path) -> None:
    run = _copy(saved, tmp_path)
    npz = run / "trajectory.npz"
    p = _array(npz, "p")
    _rewrite(npz, p=p[..., :1])
    with pytest.raises(RunDirError, match=r"array 'p' has shape \(6, 5, 1\); expected \(T, n, d\)"):
        load_run(run)
    _rewrite(npz, p=p, p_ref=_array(npz, "p_ref")[:, :3])
    with pytest.raises(
        RunDirError, match=r"array 'p_ref' has shape \(6, 3, 2\); expected \(T, n, d\) = \(6, 5, 2\)"
    ):
        load_run(run)
    _rewrite(npz, p_ref=_array(saved / "trajectory.npz", "p_ref"), t=np.array([0.0, 0.1, 0.1, 0.3, 0.4, 0.5]))
    with pytest.raises(RunDirError, match="array 't' is not increasing at index 2"):
        load_run(run)
    _rewrite(npz, t=np.arange(6.0) * 1j)
    with pytest.raises(RunDirError, match="array 't' holds complex128; expected real numbers"):
        load_run(run)
    _rewrite(npz, t=np.array(["a"] * 6))
    with pytest.raises(RunDirError, match="array 't' holds <U1; expected real numbers"):
        load_run(run)


def test_formation_arrays(saved: Path, tmp_path: Path) -> None:
    run = _copy(saved, tmp_path)
    npz = run / FORMATION_NPZ
    records = json.loads(str(_array(npz, "obstacle_records")))
    obstacles = np.array([[*r["center"], r["radius"], r["clearance"]] for r in records])  # an older run's
    _rewrite(npz, obstacle_records=None)
    for bad, match in [
        (obstacles[:, :3], r"array 'obstacles' has shape \(2, 3\); expected \(k, d \+ 2\) = \(k, 4\)"),
        (
            np.where([[True, False, False, False]], np.nan, obstacles),
            r"array 'obstacles' holds nan at index \(0, 0\)",
        ),
        (np.where([[False, False, True, False]], -1.0, obstacles), "holds the radius -1.0 in row 0"),
        (np.where([[False, False, False, True]], np.inf, obstacles), "holds the clearance inf in row 0"),
    ]:
        _rewrite(npz, obstacles=bad)
        with pytest.raises(RunDirError, match=match):
            load_run(run)
    unset = np.where([[False, False, False, True]], np.nan, obstacles)  # an older run's unset clearance
    _rewrite(npz, obstacles=unset)
    assert load_run(run).formation.obstacles[0].clearance_m is None
    _rewrite(npz, obstacles=None, obstacle_records=np.array(json.dumps([{"shape": "box", "center": [0.0]}])))
    with pytest.raises(RunDirError, match="formation.npz: cannot read its obstacles"):
        load_run(run)
    _rewrite(npz, obstacle_records=np.array(json.dumps(records)))
    _rewrite(npz, scale_ref=np.full(6, np.nan))
    with pytest.raises(RunDirError, match=r"formation.npz: array 'scale_ref' holds nan at index \(0,\)"):
        load_run(run)
    _rewrite(npz, scale_ref=np.ones(6), graph_edges=np.array([[0, 7]]), leaders=np.array([0]))
    with pytest.raises(
        RunDirError, match=r"array 'graph_edges' holds \[\[0.0, 7.0\]\]; expected drone indices in 0..4"
    ):
        load_run(run)


def test_the_summary_fields_the_figures_read(saved: Path, tmp_path: Path) -> None:
    run = _copy(saved, tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    for change, match in [
        (
            {"limits": {"d_min": "0.5"}},
            r"summary.json: limits.d_min: expected a finite number >= 0 or null, got '0.5'",
        ),
        (
            {"limits": {"v_max": float("nan")}},
            r"limits.v_max: expected a finite number >= 0 or null, got nan",
        ),
        ({"limits": {"tracking": -1.0}}, r"limits.tracking: expected a finite number >= 0 or null, got -1.0"),
        ({"plant": {"wind": {"mean_mps": [float("inf"), 0.0]}}}, "plant.wind: expected an object of finite"),
        ({"metrics": [1]}, r"summary.json: metrics: expected an object, got \[1\]"),
        ({"plant": {"wind": {"mean_mps": "x"}}}, "plant.wind: expected an object of finite numbers"),
    ]:
        (run / "summary.json").write_text(json.dumps(summary | change))
        with pytest.raises(RunDirError, match=match):
            load_run(run)
    (run / "summary.json").write_bytes(b"\xff\xfe")
    with pytest.raises(RunDirError, match="summary.json: cannot read it as JSON"):
        load_run(run)


def test_sizes_are_checked_before_reading(saved: Path, tmp_path: Path) -> None:
    """A sparse giant, a device, a directory or a zip bomb is refused before its data is read."""
    run = _copy(saved, tmp_path)
    with open(run / "summary.json", "r+b") as f:
        f.truncate(MAX_SUMMARY_BYTES + 1)
    with pytest.raises(
        RunDirError, match=r"summary.json: is 16 MiB \(16,777,217 bytes\); expected a summary.json"
    ):
        load_run(run)
    (run / "summary.json").unlink()
    (run / "summary.json").mkdir()
    with pytest.raises(RunDirError, match="summary.json: is a directory, not a regular file"):
        load_run(run)
    npz = run / "trajectory.npz"
    npz.unlink()
    os.symlink("/dev/zero", npz)
    with pytest.raises(RunDirError, match="trajectory.npz: is a character device, not a regular file"):
        load_run(run)
    npz.unlink()
    with open(npz, "wb") as f:
        f.truncate(MAX_NPZ_BYTES + 1)
    with pytest.raises(RunDirError, match=r"trajectory.npz: is 4 GiB .*; expected a numpy .npz archive"):
        load_run(run)
    npz.unlink()
    big = np.lib.format.header_data_from_array_1_0(np.zeros(1))
    big["shape"] = (2**40,)
    with zipfile.ZipFile(npz, "w") as zf, zf.open("p.npy", "w") as member:
        np.lib.format.write_array_header_1_0(member, big)  # a header promising 8 TiB, no data
    with pytest.raises(RunDirError, match=r"trajectory.npz: its arrays take 8.19e\+03 GiB decompressed"):
        load_run(run)
    npz.write_bytes(b"not a zip")
    with pytest.raises(RunDirError, match="trajectory.npz: cannot read it as a numpy .npz archive"):
        load_run(run)
