"""Shared drawing pieces: the formation's edges, drone colours, marker sizes, snapshots, envelopes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from saved_runs import short_run

pytest.importorskip("matplotlib")

from matplotlib.colors import to_rgb  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from mpcform.formation.geometry import formation_edges
from mpcform.formation.template import Template  # noqa: E402
from mpcform.outputs.drawing import (  # noqa: E402
    DRONE_COLOURS,
    EVENTS_GID,
    PER_DRONE_MAX,
    SNAPSHOT_LABEL,
    WIND_GID,
    closest_pair,
    distinct_colours,
    draw_snapshot,
    draw_wind,
    drone_colours,
    envelope,
    marker_scale,
    note_plant_events,
    path_colours,
)
from mpcform.outputs.rundata import load_run  # noqa: E402


@pytest.mark.parametrize("n", [3, 4, 8, 12])
def test_a_ring_of_n_drones_is_drawn_closed_with_n_edges(n: int) -> None:
    edges = formation_edges(Template.polygon(n, 1.5).offsets)
    assert len(edges) == n
    degree = np.bincount(np.array(edges).ravel(), minlength=n)
    assert (degree == 2).all()  # a cycle through every drone, not a spanning tree (n - 1 edges)


def test_a_planar_ring_in_space_is_closed_too() -> None:
    ring = Template.polygon(6, 1.0, dim=3).offsets
    assert len(formation_edges(ring)) == 6


def test_drones_inside_the_outline_hang_on_it_and_lines_keep_the_spanning_tree() -> None:
    grid = Template.grid(3, 3, 1.0).offsets  # 8 on the outline (4 corners, 4 on the sides), 1 inside
    edges = formation_edges(grid)
    centre = int(np.argmin(np.linalg.norm(grid - grid.mean(axis=0), axis=1)))
    outline = [e for e in edges if centre not in e]
    assert (
        len(outline) == 8
        and (np.bincount(np.array(outline).ravel(), minlength=9)[np.arange(9) != centre] == 2).all()
    )
    assert 1 <= len(edges) - 8 <= 4  # the centre hangs on its nearest neighbours
    line = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    assert formation_edges(line) == [(0, 1), (1, 2), (2, 3)]
    assert formation_edges(line[:1]) == []


def test_colours_and_markers_follow_the_swarm_size() -> None:
    few = drone_colours(PER_DRONE_MAX)
    assert len(set(few)) == PER_DRONE_MAX and all(isinstance(c, str) for c in few)
    many = drone_colours(PER_DRONE_MAX + 1)
    assert len(many) == PER_DRONE_MAX + 1 and not isinstance(many[0], str)  # a colour map
    assert marker_scale(1) == marker_scale(20) == 1.0
    assert marker_scale(40) == pytest.approx(0.5) and marker_scale(100) == pytest.approx(0.3)


def test_a_snapshot_carries_its_time() -> None:
    ax = Figure().subplots()
    draw_snapshot(ax, np.eye(3)[:, :2], [(0, 1)], "k", 12.5, 1.0)
    texts = [t for t in ax.texts if t.get_gid() == SNAPSHOT_LABEL]
    assert [t.get_text() for t in texts] == ["t = 12.5 s"]
    ax = Figure().subplots()
    draw_snapshot(ax, np.eye(3)[:, :2], [], "k", 3.0, 1.0, label="legend")
    assert ax.get_legend_handles_labels()[1] == ["snapshot t = 3 s"]


def test_envelope_is_a_band_and_a_median() -> None:
    ax = Figure().subplots()
    values = np.array([[0.0, 1.0, 5.0], [1.0, 2.0, 3.0]])
    envelope(ax, np.array([0.0, 1.0]), values, "tab:blue", "speed")
    band = [c for c in ax.collections if c.get_gid() == "envelope"]
    assert len(band) == 1 and len(ax.lines) == 1
    np.testing.assert_allclose(ax.lines[0].get_ydata(), [1.0, 2.0])


def test_closest_pair() -> None:
    p = np.array([[[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]], [[0.0, 0.0], [3.0, 0.0], [2.5, 0.0]]])
    assert closest_pair(p) == (1, 1, 2, pytest.approx(0.5))


@pytest.mark.parametrize(
    ("n", "distinct"), [(4, 4), (PER_DRONE_MAX + 1, PER_DRONE_MAX + 1), (20, 20), (21, 1)]
)
def test_plan_paths_get_a_colour_each_up_to_twenty_drones(n: int, distinct: int) -> None:
    colours = path_colours(n)
    assert len(colours) == n and len({str(c) for c in colours}) == distinct


def test_the_wind_is_an_arrow_along_its_projection(tmp_path: Path) -> None:
    short_run("swap_spatial_12_quadrotor_wind", tmp_path, steps=3)
    run = load_run(tmp_path)
    assert run.wind is not None
    mean, std = run.wind
    for plane in ((0, 1), (0, 2), (1, 2)):
        ax = Figure().subplots()
        draw_wind(ax, run, plane)
        arrows = [c for c in ax.get_children() if c.get_gid() == WIND_GID]
        label = next(t.get_text() for t in ax.texts if t.get_text().startswith("wind"))
        assert label.startswith(f"wind {np.linalg.norm(mean):.2g} m/s, gusts {std:.2g} m/s std")
        w = mean[list(plane)]
        across = np.linalg.norm(w) == 0.0
        assert len(arrows) == (0 if across else 1) and label.endswith("(across this view)") == across
        if arrows:  # tail to head in display points: along the projected wind, 28 points long
            head = arrows[0].xycoords.transform(arrows[0].xy)
            tail = arrows[0].anncoords.transform(arrows[0].xyann)
            step = (head - tail) * 72.0 / ax.figure.dpi
            np.testing.assert_allclose(step, 28.0 * w / np.linalg.norm(w), atol=1e-9)
    ax = Figure().subplots()
    draw_wind(ax, load_run(short_run_dir(tmp_path)), (0, 1))
    assert len(ax.texts) == 0  # no wind, nothing drawn


def short_run_dir(tmp_path: Path) -> Path:
    short_run("swap_planar_8", tmp_path / "calm", steps=2)
    return tmp_path / "calm"


def test_what_the_plant_reported_is_noted_in_red(tmp_path: Path) -> None:
    import json

    short_run("swap_planar_8", tmp_path, steps=2)
    summary = json.loads((tmp_path / "summary.json").read_text())
    ax = Figure().subplots()
    note_plant_events(ax, load_run(tmp_path))
    assert len(ax.texts) == 0  # the ideal plant reports nothing
    summary["plant"] |= {"floor_contacts": [3], "planning_stopped_s": {"3": 0.7}}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    note_plant_events(ax, load_run(tmp_path))
    (note,) = [t for t in ax.texts if t.get_gid() == EVENTS_GID]
    assert (
        note.get_text() == "on the floor: 3; planning stopped for drone 3 at 0.7 s"
        and note.get_color() == "tab:red"
    )


def lab(colours: list) -> np.ndarray:
    """CIE L*a*b* (D65) of matplotlib colours."""
    rgb = np.array([to_rgb(c) for c in colours])
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = linear @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])], axis=1)


@pytest.mark.parametrize(("n", "delta_e"), [(6, 25.0), (12, 25.0), (20, 15.0), (40, 1.0)])
def test_drone_colours_stay_apart_in_lab(n: int, delta_e: float) -> None:
    colours = distinct_colours(n)
    d = np.linalg.norm(lab(colours)[:, None] - lab(colours)[None], axis=-1)
    assert d[np.triu_indices(n, 1)].min() > delta_e
    if n <= 20:  # the time series' six first, as the plans' path colours (top view and projections)
        assert [to_rgb(c) for c in colours[:PER_DRONE_MAX]] == [to_rgb(c) for c in DRONE_COLOURS]
        assert [to_rgb(c) for c in path_colours(n)] == [to_rgb(c) for c in colours]
