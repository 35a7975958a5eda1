"""Plan figures of a run (matplotlib, Agg canvas): ``top_view.png`` and, for spatial runs,
``view_3d.png`` as three projections (x-y, x-z, y-z), so that paths through the centre and the
clearance between drones stay readable (a perspective 3-D plot hides both).

Every plan shows the drone paths (one colour per drone up to six drones, else thin shades), and
for a plant run the flown (true, dense) paths dotted over them, the reference paths dashed on top
(above six drones only those of eight drones on the formation's outline),
formation snapshots coloured by time (colour bar) and labelled ``t = ... s``, start and end,
obstacles with their required clearance, the closest pair at the moment of minimum separation,
and for consensus runs the communication graph and the leaders.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.figure import Figure
from matplotlib.text import Annotation

from mpcform.outputs.drawing import (
    FLOWN_GID,
    PATH_COLOURS_MAX,
    PER_DRONE_MAX,
    REFERENCE_STYLE,
    SNAPSHOT_LABEL,
    closest_pair,
    display_rows,
    draw_graph,
    draw_leaders,
    draw_obstacles,
    draw_snapshot,
    draw_wind,
    mark_closest_pair,
    marker_scale,
    note_plant_events,
    path_colours,
    plan_size,
    reference_subset,
    skeleton_edges,
    snapshot_indices,
    time_colour,
)
from mpcform.outputs.rundata import RunData

AXIS_NAMES = ("x", "y", "z")
PROJECTIONS = ((0, 1), (0, 2), (1, 2))


def new_figure(size_in: tuple[float, float]) -> Figure:
    """A figure on its own Agg canvas (no pyplot, no global state), constrained layout."""
    fig = Figure(figsize=size_in, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def top_view(run: RunData) -> Figure:
    """Trajectories in the x-y plane with time-labelled snapshots, obstacles and the closest pair."""
    graph = run.formation.graph_edges is not None
    width, height = plan_size(run, width_in=8.0)
    fig = new_figure((width + 1.8 * graph, height))
    if graph:
        ax, graph_ax = fig.subplots(1, 2, width_ratios=(width, 1.8))
        draw_graph(graph_ax, run)
    else:
        ax = fig.subplots()
    if skeleton_edges(run):
        draw_plan(ax, run, (0, 1), labels="text")
    else:  # a swarm drawn as dots: times in the legend, fewer snapshots
        draw_plan(ax, run, (0, 1), labels="legend", snapshots=key_moments(run))
    ax.set_aspect("equal", adjustable="box")
    ax.set_title(f"Top view: {run.label}", fontsize="medium")
    _colour_bar(fig, run, [ax])
    legend_below(fig, ax)
    fit_height(fig, ax)
    place_time_labels(ax)
    return fig


def view_3d(run: RunData) -> Figure:
    """A spatial run seen along each axis: x-y, x-z and y-z projections side by side."""
    fig = new_figure((15.0, 5.8))
    axes = fig.subplots(1, 3)
    for k, (ax, plane) in enumerate(zip(axes, PROJECTIONS, strict=True)):
        draw_plan(ax, run, plane, labels="legend" if k == 0 else "none", snapshots=key_moments(run))
        ax.set_title(f"{AXIS_NAMES[plane[0]]}-{AXIS_NAMES[plane[1]]} projection", fontsize="medium")
    fig.suptitle(f"Spatial run in three projections: {run.label}", fontsize="medium")
    _colour_bar(fig, run, list(axes))
    legend_below(fig, axes[0], ncol=5)
    return fig


def draw_plan(
    ax: Axes,
    run: RunData,
    plane: tuple[int, int],
    *,
    labels: str = "text",
    snapshots: np.ndarray | None = None,
) -> None:
    """Paths, reference paths, snapshots, start and end, obstacles, graph and closest pair in one plane."""
    a, b = plane
    p, ref, t = run.trajectory.positions_m, run.trajectory.reference_m, run.trajectory.t_s
    draw_obstacles(ax, run, plane)
    few, coloured = run.n <= PER_DRONE_MAX, run.n <= PATH_COLOURS_MAX
    colours = path_colours(run.n)
    paths = "drone paths, a colour per drone" if coloured else "drone paths"
    for i in range(run.n):
        label = f"drone {i}" if few else (paths if i == 0 else None)
        if label is not None and run.flown is not None:
            label += " (control samples)"
        ax.plot(
            p[:, i, a],
            p[:, i, b],
            color=colours[i],
            lw=2.4 if few else 1.3 if coloured else 0.7,
            alpha=0.7 if few else 0.9 if coloured else 0.6,
            zorder=2,
            label=label,
        )
    true = run.flown
    if true is not None:  # a plant run: where the drones really flew, thin and dotted over the samples
        q = true.positions_m[display_rows(true.t_s.shape[0])]
        for i in range(run.n):
            label = "flown path (true)" if i == 0 else None
            colour = colours[i] if coloured else "k"
            ax.plot(
                q[:, i, a], q[:, i, b], color=colour, lw=0.8, ls=":", zorder=2.4, label=label, gid=FLOWN_GID
            )
    if np.ptp(ref, axis=0).max() > 0:
        shown = reference_subset(run, plane)
        some = "" if shown.shape[0] == run.n else f" ({shown.shape[0]} of {run.n} drones, on the outline)"
        for k, i in enumerate(shown.tolist()):
            label = f"reference path{some}" if k == 0 else None
            ax.plot(ref[:, i, a], ref[:, i, b], label=label, **REFERENCE_STYLE)
    else:  # a constant reference: its points, not paths
        ax.scatter(
            ref[0, :, a],
            ref[0, :, b],
            marker="x",
            s=30,
            color="k",
            lw=0.8,
            zorder=4.5,
            label="reference p*_i (fixed)",
        )
    edges = skeleton_edges(run)
    cmap, norm = time_colour(run)
    size = marker_scale(run.n)
    idx = snapshot_indices(run) if snapshots is None else snapshots
    for k, j in enumerate(idx.tolist()):
        anchor = (k * run.n) // len(idx)  # labels spread over the drones: nested shapes stay legible
        draw_snapshot(ax, p[j][:, [a, b]], edges, cmap(norm(t[j])), float(t[j]), size, labels, anchor)
    end = p[-1][:, [a, b]]
    start = p[0][:, [a, b]]
    hollow: dict[str, Any] = {"facecolors": "none", "edgecolors": "k", "lw": 0.8, "zorder": 4}
    ax.scatter(start[:, 0], start[:, 1], marker="o", s=40 * size, label="start", **hollow)
    ax.scatter(end[:, 0], end[:, 1], marker="s", s=26 * size, label="end", **hollow)
    draw_leaders(ax, end, run)
    mark_closest_pair(ax, run, plane)
    draw_wind(ax, run, plane)
    note_plant_events(ax, run)
    ax.set(xlabel=f"{AXIS_NAMES[a]} [m]", ylabel=f"{AXIS_NAMES[b]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)


def legend_below(fig: Figure, ax: Any, ncol: int = 4) -> None:
    """A compact legend of ``ax`` under the figure (off the data), one entry per kind of element."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize="small", frameon=False)


def fit_height(fig: Figure, ax: Axes, rounds: int = 3) -> None:
    """Shorten ``fig`` by the height its equal-aspect ``ax`` leaves empty in its layout box: no
    blank band between the plot and the legend under it."""
    for _ in range(rounds):
        fig.canvas.draw()
        box, used = ax.get_position(original=True), ax.get_position()
        width, height = fig.get_size_inches()
        empty = (box.height - used.height) * height
        if empty < 0.02:
            return
        fig.set_size_inches(width, height - empty)


LABEL_GAP_PT = 9.0  # from a snapshot's drone to the nearest edge of its time label
LABEL_SIDES = (0, 1, -1, 2, -2, 3, -3, 4)  # eighths of a turn from the first choice


def place_time_labels(ax: Axes) -> None:
    """Put each ``t = ... s`` label on the side of its drone (eight tried, the first away from the
    snapshot's centre as drawn) that covers the fewest drone markers, then earlier labels and the
    axes' edge: none if it can. Call it on a figure laid out at its final size."""
    fig = cast(Figure, ax.figure)
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    points = [c.get_offset_transform().transform(c.get_offsets()) for c in ax.collections]
    markers = np.concatenate([np.empty((0, 2)), *[q for q in points if q.size]])
    margin = 3.0 * fig.dpi / 72  # a marker's half size and some air [px]
    frame = ax.get_window_extent(renderer)
    taken: list[Any] = []
    for label in [t for t in ax.texts if t.get_gid() == SNAPSHOT_LABEL and isinstance(t, Annotation)]:
        first = float(np.arctan2(label.xyann[1], label.xyann[0]))
        tried = []
        for turn in LABEL_SIDES:
            _set_side(label, first + turn * np.pi / 4)
            box = label.get_window_extent(renderer).padded(2.0)
            cost = float(_covered(box, markers, margin).sum() + sum(box.overlaps(o) for o in taken))
            cost += 0.5 * float(
                box.x0 < frame.x0 or box.x1 > frame.x1 or box.y0 < frame.y0 or box.y1 > frame.y1
            )
            tried.append((cost, turn))
            if cost == 0:
                break
        _set_side(label, first + min(tried)[1] * np.pi / 4)
        taken.append(label.get_window_extent(renderer).padded(2.0))


def _set_side(label: Annotation, angle: float) -> None:
    """``label`` :data:`LABEL_GAP_PT` from its point towards ``angle``, aligned on that side."""
    u = np.cos(angle), np.sin(angle)
    label.xyann = (LABEL_GAP_PT * u[0], LABEL_GAP_PT * u[1])
    label.set_horizontalalignment("left" if u[0] > 0.3 else "right" if u[0] < -0.3 else "center")
    label.set_verticalalignment("bottom" if u[1] > 0.3 else "top" if u[1] < -0.3 else "center")


def _covered(box: Any, points: np.ndarray, margin: float) -> np.ndarray:
    """Which ``points`` (m, 2) [px] lie within ``margin`` of ``box``."""
    lo, hi = np.array([box.x0, box.y0]) - margin, np.array([box.x1, box.y1]) + margin
    return np.asarray(((points >= lo) & (points <= hi)).all(axis=1))


def key_moments(run: RunData) -> np.ndarray:
    """Start, moment of minimum separation and end: the snapshots of a spatial run."""
    last = run.trajectory.t_s.shape[0] - 1
    k = closest_pair(run.trajectory.positions_m)[0] if run.n >= 2 else last // 2
    return np.unique(np.array([0, k, last]))


def _colour_bar(fig: Figure, run: RunData, axes: list[Any]) -> None:
    cmap, norm = time_colour(run)
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=axes, shrink=0.6, pad=0.01, aspect=25)
    bar.set_label("snapshot time t [s]")
