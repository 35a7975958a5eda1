"""Figures on the Agg canvas: files written, non-empty, with provenance; the same from memory; lazy import."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from saved_runs import short_run

pytest.importorskip("matplotlib")
PIL = pytest.importorskip("PIL.Image")

from mpcform.outputs import figures  # noqa: E402
from mpcform.outputs.rundata import load_run  # noqa: E402


def png(path: Path) -> tuple[int, int]:
    assert path.exists() and path.stat().st_size > 5_000, f"{path.name} is missing or nearly empty"
    with PIL.open(path) as im:
        assert im.format == "PNG"
        return im.size


def test_planar_run_figures(tmp_path: Path) -> None:
    short_run("obstacles_planar", tmp_path, steps=30)
    paths = figures.plot_run(load_run(tmp_path), tmp_path / "plots")
    names = {p.name for p in paths}
    assert names == {"top_view.png", "tracking_error.png", "speed.png", "separation.png", "scale.png"}
    assert names < set(figures.FIGURE_FILES)
    for path in paths:
        width, height = png(path)
        assert width >= 600 and height >= 300
    with PIL.open(tmp_path / "plots" / "top_view.png") as im:
        assert "obstacles_planar" in im.text["Title"] and "sha256" in im.text["Description"]
        assert im.text["Software"].startswith("mpcform") and im.text["Source"] == str(tmp_path)


def test_spatial_run_adds_a_3d_view_and_one_drone_skips_pair_figures(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path / "swap", steps=10)
    names = {p.name for p in figures.plot_run(load_run(tmp_path / "swap"), tmp_path / "swap" / "plots")}
    assert "view_3d.png" in names and "separation.png" in names
    short_run("go_to_goal", tmp_path / "one", steps=10)
    names = {p.name for p in figures.plot_run(load_run(tmp_path / "one"), tmp_path / "one" / "plots")}
    assert names == {"top_view.png", "view_3d.png", "tracking_error.png", "speed.png"}


def test_scale_without_formation_data_is_relative(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path, steps=20, formation=False)
    fig = figures.scale(load_run(tmp_path))
    ax = fig.axes[0]
    assert ax.get_ylabel() == "formation scale s (relative to the start)"
    best_fit, reference = (line.get_ydata() for line in ax.get_lines())
    assert best_fit[0] == pytest.approx(1.0) and reference[0] == pytest.approx(1.0)


def test_compare_runs(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path / "a", steps=20)
    short_run("go_to_goal", tmp_path / "b", steps=20)
    runs = [load_run(tmp_path / "a"), load_run(tmp_path / "b")]
    png(figures.compare_runs(runs, tmp_path / "cmp" / "compare.png"))


def test_plotting_is_imported_only_when_asked_for() -> None:
    code = (
        "import sys, mpcform, mpcform.cli.main, mpcform.cli.handlers, mpcform.outputs.export\n"
        "import mpcform.outputs.rundata, mpcform.outputs.compare, mpcform.sim.metrics\n"
        "assert 'matplotlib' not in sys.modules, 'matplotlib imported with the package'\n"
        "import mpcform.outputs.figures, mpcform.outputs.animation\n"
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot (global state) imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
