"""Figures and animations on the Agg canvas: files written, non-empty, with provenance; lazy import."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from saved_runs import short_run

pytest.importorskip("matplotlib")
PIL = pytest.importorskip("PIL.Image")

from mpcform.outputs import plotting  # noqa: E402
from mpcform.outputs.rundata import load_run  # noqa: E402


def png(path: Path) -> tuple[int, int]:
    assert path.exists() and path.stat().st_size > 5_000, f"{path.name} is missing or nearly empty"
    with PIL.open(path) as im:
        assert im.format == "PNG"
        return im.size


def test_planar_run_figures(tmp_path: Path) -> None:
    short_run("obstacles_planar", tmp_path, steps=30)
    paths = plotting.plot_run(load_run(tmp_path), tmp_path / "plots")
    names = {p.name for p in paths}
    assert names == {"top_view.png", "tracking_error.png", "speed.png", "separation.png", "scale.png"}
    for path in paths:
        width, height = png(path)
        assert width >= 600 and height >= 300
    with PIL.open(tmp_path / "plots" / "top_view.png") as im:
        assert "obstacles_planar" in im.text["Title"] and "sha256" in im.text["Description"]
        assert im.text["Software"].startswith("mpcform")


def test_spatial_run_adds_a_3d_view_and_one_drone_skips_pair_figures(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path / "swap", steps=10)
    names = {p.name for p in plotting.plot_run(load_run(tmp_path / "swap"), tmp_path / "swap" / "plots")}
    assert "view_3d.png" in names and "separation.png" in names
    short_run("go_to_goal", tmp_path / "one", steps=10)
    names = {p.name for p in plotting.plot_run(load_run(tmp_path / "one"), tmp_path / "one" / "plots")}
    assert names == {"top_view.png", "view_3d.png", "tracking_error.png", "speed.png"}


def test_series() -> None:
    offsets = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 1.0]])
    assert plotting.formation_edges(offsets) == [(0, 1), (1, 2), (2, 3)]
    assert plotting.formation_edges(offsets[:1]) == []


def test_scale_follows_the_worked_example(tmp_path: Path) -> None:
    run = short_run("worked_example", tmp_path, steps=200)
    data = load_run(tmp_path)
    fitted = plotting.fitted_scales(data, data.positions_m)
    assert data.scale_ref is not None
    assert np.allclose(fitted, data.scale_ref, atol=0.02)  # s(t) = 2 - e^-t, tracked within O(dt)
    assert fitted[-1] == pytest.approx(2.0 - np.exp(-run.simulation.t_s[-1]), abs=1e-2)


def test_animation(tmp_path: Path) -> None:
    short_run("swap_planar_8", tmp_path, steps=30)
    path = plotting.animate_run(load_run(tmp_path), tmp_path / "plots" / "flight.gif", max_frames=6)
    with PIL.open(path) as im:
        assert im.format == "GIF" and im.n_frames == 6 and im.size[0] > 200


def test_spatial_animation(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path, steps=10)
    path = plotting.animate_run(load_run(tmp_path), tmp_path / "a.gif", max_frames=3)
    with PIL.open(path) as im:
        assert im.n_frames == 3


def test_compare_runs(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path / "a", steps=20)
    short_run("go_to_goal", tmp_path / "b", steps=20)
    runs = [load_run(tmp_path / "a"), load_run(tmp_path / "b")]
    png(plotting.compare_runs(runs, tmp_path / "cmp" / "compare.png"))


def test_plotting_is_imported_only_when_asked_for() -> None:
    code = (
        "import sys, mpcform, mpcform.cli.main, mpcform.outputs.export, mpcform.outputs.rundata\n"
        "assert 'matplotlib' not in sys.modules, 'matplotlib imported with the package'\n"
        "import mpcform.outputs.plotting\n"
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot (global state) imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
