"""Figures on the Agg canvas: files written, non-empty, with provenance; envelopes above six drones,
the speed axis, obstacle clearance, the scale only where the drones hold the shape and the consensus
estimates; lazy import."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from saved_runs import SCENARIOS, short_run, shortened

pytest.importorskip("matplotlib")
PIL = pytest.importorskip("PIL.Image")

import numpy as np  # noqa: E402

from mpcform.outputs import figures  # noqa: E402
from mpcform.outputs.drawing import PER_DRONE_MAX  # noqa: E402
from mpcform.outputs.rundata import formation_data, load_run, write_formation_npz  # noqa: E402
from mpcform.run.runner import run_scenario  # noqa: E402
from mpcform.scenario.load import load_scenario  # noqa: E402
from mpcform.sim.metrics import command_speeds_mps  # noqa: E402


def png(path: Path) -> tuple[int, int]:
    assert path.exists() and path.stat().st_size > 5_000, f"{path.name} is missing or nearly empty"
    with PIL.open(path) as im:
        assert im.format == "PNG"
        return im.size


def test_planar_run_figures(tmp_path: Path) -> None:
    short_run("obstacles_planar", tmp_path, steps=30)
    paths = figures.plot_run(load_run(tmp_path), tmp_path / "plots")
    names = {p.name for p in paths}
    assert names == {
        "top_view.png",
        "tracking_error.png",
        "speed.png",
        "separation.png",
        "scale.png",
        "clearance.png",
    }
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


def test_scale_is_not_drawn_while_a_permuted_start_is_out_of_shape(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path, steps=10)  # explicit start: the mirrored goal
    ax = figures.scale(load_run(tmp_path)).axes[0]
    best_fit = np.asarray(ax.get_lines()[0].get_ydata())
    assert np.isnan(best_fit[0])  # no scale where there is no formation
    assert "not drawn" in ax.get_xlabel() and not ax.texts  # under the time axis, not over the curves


def estimate_artists(ax) -> dict[str, list]:
    """The scale figure's artists by gid: drone (or median) estimates, leaders, the band, notes."""
    gids = (figures.ESTIMATE_GID, figures.LEADER_GID)
    found = {gid: [line for line in ax.get_lines() if line.get_gid() == gid] for gid in gids}
    found["envelope"] = [c for c in ax.collections if c.get_gid() == "envelope"]
    found["scale-note"] = [t for t in [*ax.texts, ax.xaxis.label] if t.get_gid() == "scale-note"]
    return found


def test_scale_draws_the_consensus_estimates_as_an_envelope_above_six_drones(tmp_path: Path) -> None:
    short_run("consensus_ring", tmp_path, steps=120)
    run = load_run(tmp_path)
    s_hat = run.trajectory.scale_estimates
    assert s_hat is not None and run.n == 8 > PER_DRONE_MAX
    ax = figures.scale(run).axes[0]
    found = estimate_artists(ax)
    assert len(found["envelope"]) == 1 and not found["scale-note"]
    (median,) = found[figures.ESTIMATE_GID]
    np.testing.assert_array_equal(median.get_ydata(), np.median(s_hat, axis=1))
    (leader,) = found[figures.LEADER_GID]
    np.testing.assert_array_equal(leader.get_ydata(), s_hat[:, 0])
    assert leader.get_marker() == "*" and leader.get_linestyle() == "-"  # the band hides the leader
    band = found["envelope"][0].get_paths()[0].vertices[:, 1]
    assert band.min() == pytest.approx(s_hat.min()) and band.max() == pytest.approx(s_hat.max())
    labels = ax.get_legend_handles_labels()[1]
    assert "leader 0 (sees s*)" in labels and "reference s*(t)" in labels
    assert not any(label.startswith("drone ") for label in labels)


def test_scale_draws_one_estimate_per_drone_up_to_six_and_stars_every_leader(tmp_path: Path) -> None:
    text = (SCENARIOS / "consensus_ring.toml").read_text()
    text = text.replace("n = 8", "n = 5").replace("leaders = [0]", "leaders = [0, 2]")
    (tmp_path / "ring5.toml").write_text(text)
    scenario = shortened(load_scenario(tmp_path / "ring5.toml"), 60)
    result = run_scenario(scenario, tmp_path / "out")
    write_formation_npz(tmp_path / "out", formation_data(scenario, result.simulation.t_s))
    run = load_run(tmp_path / "out")
    s_hat = run.trajectory.scale_estimates
    assert s_hat is not None and s_hat.shape == (61, 5)
    found = estimate_artists(figures.scale(run).axes[0])
    assert not found["envelope"] and not found["scale-note"]
    lines = found[figures.ESTIMATE_GID]
    assert [line.get_label() for line in lines] == [f"drone {i}: s_hat_{i}" for i in range(5)]
    for i, line in enumerate(lines):
        np.testing.assert_array_equal(line.get_ydata(), s_hat[:, i])
    leaders = found[figures.LEADER_GID]
    assert [line.get_label() for line in leaders][0] == "leaders 0, 2 (see s*)"
    for i, line in zip((0, 2), leaders, strict=True):  # stars on the drone's own line
        np.testing.assert_array_equal(line.get_ydata(), s_hat[:, i])
        assert line.get_marker() == "*" and line.get_linestyle() == "None"


def test_scale_of_a_run_without_estimates_or_without_formation_data(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path / "mpc", steps=10)
    found = estimate_artists(figures.scale(load_run(tmp_path / "mpc")).axes[0])
    assert not any(found.values())  # no estimates recorded, nothing to say
    short_run("consensus_ring", tmp_path / "ring", steps=10, formation=False)
    ax = figures.scale(load_run(tmp_path / "ring")).axes[0]
    found = estimate_artists(ax)
    assert not found[figures.ESTIMATE_GID] and not found[figures.LEADER_GID]
    assert "estimates s_hat_i not drawn" in found["scale-note"][0].get_text()
    best_fit = ax.get_lines()[0]
    assert best_fit.get_color() == figures.MEDIAN_COLOUR  # drawn as without estimates


@pytest.mark.parametrize(
    ("data_max", "v_max", "top"), [(1.0, 1.5, 1.65), (1.0, 2.5, 1.1), (1.0, None, 1.1), (2.0, 1.0, 2.2)]
)
def test_speed_axis_ends_at_most_10_percent_above_what_it_must_show(
    data_max: float, v_max: float | None, top: float
) -> None:
    assert figures.speed_axis_top(data_max, v_max) == pytest.approx(top)


def test_speed_figure_axis_and_off_scale_v_max(tmp_path: Path) -> None:
    short_run("consensus_ring", tmp_path, steps=40)  # speeds far below v_max
    run = load_run(tmp_path)
    ax = figures.speeds(run).axes[0]
    peak = float(command_speeds_mps(run.trajectory).max())
    assert run.v_max_mps is not None and run.v_max_mps > 2 * peak
    assert ax.get_ylim()[1] == pytest.approx(1.1 * peak)
    assert any("off scale" in t.get_text() for t in ax.texts)


def test_envelopes_above_six_drones_one_line_per_drone_below(tmp_path: Path) -> None:
    short_run("swap_planar_8", tmp_path / "eight", steps=10)
    many = load_run(tmp_path / "eight")
    assert many.n > PER_DRONE_MAX
    for fig in (figures.speeds(many), figures.tracking_error(many)):
        ax = fig.axes[0]
        assert [c.get_gid() for c in ax.collections].count("envelope") == 1
        assert not any(label.startswith("drone ") for label in ax.get_legend_handles_labels()[1])
    short_run("mission_obstacle_gap", tmp_path / "four", steps=10)
    few = load_run(tmp_path / "four")
    ax = figures.speeds(few).axes[0]
    assert "envelope" not in [c.get_gid() for c in ax.collections]
    assert sum(label.startswith("drone ") for label in ax.get_legend_handles_labels()[1]) == few.n


def test_clearance_against_the_required_clearance(tmp_path: Path) -> None:
    short_run("mission_obstacle_gap", tmp_path, steps=200)
    run = load_run(tmp_path)
    ax = figures.clearance(run).axes[0]
    labels = ax.get_legend_handles_labels()[1]
    assert sum("closest drone" in label for label in labels) == len(run.formation.obstacles)
    assert "required clearance 0.25 m" in labels  # d_min / 2 with d_min = 0.5 m
    lowest = min(
        float(np.nanmin(line.get_ydata())) for line in ax.get_lines() if "closest" in str(line.get_label())
    )
    assert lowest == pytest.approx(run.summary["metrics"]["min_obstacle_clearance"])


def test_compare_runs(tmp_path: Path) -> None:
    short_run("worked_example", tmp_path / "a", steps=20)
    short_run("go_to_goal", tmp_path / "b", steps=20)
    runs = [load_run(tmp_path / "a"), load_run(tmp_path / "b")]
    png(figures.compare_runs(runs, tmp_path / "cmp" / "compare.png"))


def test_plotting_is_imported_only_when_asked_for() -> None:
    code = (
        "import sys, mpcform, mpcform.cli.main, mpcform.cli.handlers, mpcform.outputs.flight.export\n"
        "import mpcform.outputs.rundata, mpcform.outputs.compare, mpcform.sim.metrics\n"
        "assert 'matplotlib' not in sys.modules, 'matplotlib imported with the package'\n"
        "import mpcform.outputs.figures, mpcform.outputs.animation\n"
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot (global state) imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
