"""Plan figures: time-labelled snapshots, closed rings, the closest pair, the communication graph,
three projections of a spatial run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from saved_runs import short_run

pytest.importorskip("matplotlib")

from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

from mpcform.outputs.drawing import (  # noqa: E402
    REFERENCE_PATHS_MAX,
    SNAPSHOT_LABEL,
    closest_pair,
    snapshot_indices,
    time_colour,
)
from mpcform.outputs.plan_views import top_view, view_3d  # noqa: E402
from mpcform.outputs.rundata import load_run  # noqa: E402


def test_top_view_snapshots_carry_time_labels_and_rings_are_closed(tmp_path: Path) -> None:
    short_run("consensus_ring", tmp_path, steps=60)
    run = load_run(tmp_path)
    fig = top_view(run)
    ax = fig.axes[0]
    idx = snapshot_indices(run)
    labels = [t.get_text() for t in ax.texts if t.get_gid() == SNAPSHOT_LABEL]
    assert labels == [f"t = {run.trajectory.t_s[j]:.3g} s" for j in idx]
    assert len(set(labels)) == len(labels) >= 3
    cmap, norm = time_colour(run)
    for j in idx:  # each snapshot: n edges in its time's colour (a closed ring of 8)
        colour = to_rgba(cmap(norm(run.trajectory.t_s[j])))
        edges = [line for line in ax.get_lines() if to_rgba(line.get_color()) == colour]
        assert len(edges) == run.n
    assert any(label.startswith("closest pair") for label in ax.get_legend_handles_labels()[1])


def test_consensus_run_shows_its_graph_and_leader(tmp_path: Path) -> None:
    short_run("consensus_ring", tmp_path, steps=10)
    run = load_run(tmp_path)
    assert run.formation.graph_edges is not None and run.formation.leaders == (0,)
    fig = top_view(run)
    graph_ax = fig.axes[1]
    assert "communication graph" in graph_ax.get_title() and len(graph_ax.get_lines()) == 8
    assert any(label.startswith("leader") for label in fig.axes[0].get_legend_handles_labels()[1])


def test_spatial_run_in_three_projections(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path, steps=40)
    fig = view_3d(load_run(tmp_path))
    titles = [ax.get_title() for ax in fig.axes[:3]]
    assert titles == ["x-y projection", "x-z projection", "y-z projection"]
    assert all(ax.name == "rectilinear" for ax in fig.axes)  # no perspective 3-D axes
    snapshot_labels = [label for label in fig.axes[0].get_legend_handles_labels()[1] if "snapshot" in label]
    assert len(snapshot_labels) == 3 and all(label.startswith("snapshot t = ") for label in snapshot_labels)
    paths = [line for line in fig.axes[0].get_lines() if line.get_xydata().shape[0] == 41]  # one per drone
    assert len(paths) == 12 and len({to_rgba(line.get_color()) for line in paths}) == 12  # no grey tangle
    assert "drone paths, a colour per drone" in fig.axes[0].get_legend_handles_labels()[1]


def test_snapshots_span_the_motion_not_the_idle_tail(tmp_path: Path) -> None:
    short_run("mission_obstacle_gap", tmp_path, steps=400)  # hovers at its goal for the last ~3 s
    run = load_run(tmp_path)
    idx = snapshot_indices(run)
    assert idx[0] == 0 and len(idx) == 4 and idx[-1] < run.trajectory.t_s.shape[0] - 20
    speed = np.linalg.norm(run.trajectory.commands_mps, axis=-1).max(axis=1)
    assert speed[idx[-1] - 1] > 0.01 * speed.max() >= speed[idx[-1] + 1 :].max()


def test_a_swarm_draws_the_reference_paths_of_its_outline_only(tmp_path: Path) -> None:
    short_run("formation_flight_100", tmp_path, steps=20)
    run = load_run(tmp_path)
    ax = top_view(run).axes[0]
    dashed = [line for line in ax.get_lines() if line.get_label().startswith("reference path")]
    arcs = [line for line in ax.get_lines() if line.get_linestyle() == "--" and line.get_color() == "k"]
    assert len(dashed) == 1 and "of 100 drones, on the outline" in dashed[0].get_label()
    assert 1 <= len(arcs) <= REFERENCE_PATHS_MAX  # the 4 corners of the grid
    ends = np.array([line.get_xydata()[0] for line in arcs])
    outline = run.trajectory.reference_m[0]
    assert all(np.abs(outline - end).sum(axis=1).min() < 1e-9 for end in ends)


def test_projected_circles_of_the_closest_pair_overlap_only_for_a_breach(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path, steps=40)
    run = load_run(tmp_path)
    k, i, j, dist = closest_pair(run.trajectory.positions_m)
    assert run.d_min_m is not None and dist >= run.d_min_m - 1e-9  # no breach
    for ax, plane in zip(view_3d(run).axes[:3], ((0, 1), (0, 2), (1, 2)), strict=True):
        circles = [patch for patch in ax.patches if isinstance(patch, Circle)]
        assert len(circles) == 2
        centres = np.array([c.center for c in circles])
        seen = np.linalg.norm(centres[1] - centres[0])
        np.testing.assert_allclose(centres, run.trajectory.positions_m[k][[i, j]][:, list(plane)])
        assert circles[0].radius == pytest.approx(run.d_min_m / 2 * seen / dist)
        assert 2 * circles[0].radius <= seen + 1e-12  # they touch at most: not read as a violation


def test_the_legend_sits_under_the_top_view_without_an_empty_band(tmp_path: Path) -> None:
    short_run("swap_spatial_12", tmp_path, steps=40)  # the colour bar narrows the equal-aspect plot
    fig = top_view(load_run(tmp_path))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax, legend = fig.axes[0], fig.legends[0].get_window_extent(renderer)
    plot = ax.get_tightbbox(renderer)  # the axes with their tick labels and x label
    assert 0 <= plot.y0 - legend.y1 <= 0.25 * fig.dpi  # at most a quarter inch between them
    assert ax.get_position().height == pytest.approx(ax.get_position(original=True).height, rel=0.01)


@pytest.mark.parametrize("name", ["worked_example", "swap_planar_8"])
def test_time_labels_cover_no_drone_marker(tmp_path: Path, name: str) -> None:
    short_run(name, tmp_path, steps=60)
    fig = top_view(load_run(tmp_path))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[0]
    markers = np.concatenate(
        [c.get_offset_transform().transform(c.get_offsets()) for c in ax.collections if len(c.get_offsets())]
    )
    labels = [t for t in ax.texts if t.get_gid() == SNAPSHOT_LABEL]
    assert labels[0].get_text() == "t = 0 s"
    for label in labels:
        box = label.get_window_extent(renderer)
        inside = (markers >= [box.x0, box.y0]) & (markers <= [box.x1, box.y1])
        assert not inside.all(axis=1).any(), label.get_text()
        anchor = ax.transData.transform(label.xy)
        assert np.hypot(*(anchor - np.clip(anchor, [box.x0, box.y0], [box.x1, box.y1]))) >= 4.0  # beside it
