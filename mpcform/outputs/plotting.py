"""Figures and animations of runs (matplotlib, Agg backend; ``pip install "mpcform[plot]"``).

Imported only when plots are asked for (never by ``mpcform/__init__``). Figures are built
with matplotlib's object API on an Agg canvas, never through pyplot: no window opens, no
global backend is switched, and nothing stays in pyplot's figure registry. Every figure is drawn
from a :class:`~mpcform.outputs.rundata.RunData`, so ``mpcform run --plot`` and ``mpcform plot DIR``
draw the same files:

- ``top_view.png``: trajectories in the x-y plane, formation snapshots (drones joined by the
  template's minimum spanning tree), start and end, reference paths, obstacles;
- ``view_3d.png`` (spatial runs): the same in 3D;
- ``tracking_error.png``: max and median over drones of ``||p_i - p*_i||`` [m], log scale;
- ``separation.png``: minimum distance between two drones [m] with the d_min line;
- ``speed.png``: command speeds ``||u_i||`` [m/s] (zero-order hold) with the v_max line;
- ``scale.png``: best-fit scale of the positions (Umeyama) and the reference's scale;
- ``flight.gif`` (:func:`animate_run`): the flight with trails.

PNG files carry the run's provenance (scenario, hash, seed, versions) in their metadata.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from matplotlib.ticker import MaxNLocator
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial.distance import pdist, squareform

from mpcform._validate import Array
from mpcform.formation.geometry import min_pair_distance
from mpcform.formation.kinematics import fit_formation
from mpcform.formation.template import Template
from mpcform.outputs.rundata import RunData

FIGURE_FILES = ("top_view.png", "view_3d.png", "tracking_error.png", "separation.png", "speed.png",
                "scale.png")  # fmt: skip
ANIMATION_FILE = "flight.gif"
COMPARE_FILE = "compare.png"
SNAPSHOTS = 5
DRONE_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
                 "tab:olive", "tab:cyan")  # fmt: skip
PER_DRONE_MAX = len(DRONE_COLOURS)  # up to this many drones: one legend entry / speed line per drone
LINESTYLES = ("-", "--", ":", "-.")  # runs of a comparison: overlapping curves stay visible
LOG_FLOOR_M = 1e-14  # tracking errors below this (exact starts) are not drawn on the log axis
DPI = 110


def plot_run(run: RunData, out_dir: str | Path) -> list[Path]:
    """Write the figures of ``run`` into ``out_dir`` (created); returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures: list[tuple[str, Figure]] = [("top_view.png", top_view(run))]
    if run.dim == 3:
        figures.append(("view_3d.png", view_3d(run)))
    figures += [("tracking_error.png", tracking_error(run)), ("speed.png", speeds(run))]
    if run.n >= 2:  # one drone has neither separation nor scale
        figures += [("separation.png", separation(run)), ("scale.png", scale(run))]
    paths = []
    for name, fig in figures:
        paths.append(_save(fig, out / name, run))
    return paths


# ---- single runs ------------------------------------------------------------------------
def top_view(run: RunData) -> Figure:
    """Trajectories in the x-y plane with formation snapshots and obstacles."""
    fig = _figure(_plan_size(run))
    ax = fig.subplots()
    _draw_obstacles(ax, run)
    p, ref = run.positions_m, run.reference_m
    colours = _drone_colours(run.n)
    for i in range(run.n):
        ax.plot(ref[:, i, 0], ref[:, i, 1], color="0.6", lw=0.8, ls="--",
                label="reference path" if i == 0 else None)  # fmt: skip
        label = f"drone {i}" if run.n <= PER_DRONE_MAX else ("drone paths" if i == 0 else None)
        ax.plot(p[:, i, 0], p[:, i, 1], color=colours[i], lw=1.2, label=label)
    edges = formation_edges(run.offsets_m)
    for j, tj in zip(*_snapshot_indices(run), strict=True):
        shade = colormaps["Greys"](0.45 + 0.55 * j / max(1, run.t_s.shape[0] - 1))
        _draw_formation(ax, p[j, :, :2], edges, shade, f"formation at t = {tj:.3g} s")
    size = _marker_scale(run.n)
    ax.scatter(p[0, :, 0], p[0, :, 1], marker="o", s=28 * size, facecolors="none", edgecolors="tab:green",
               zorder=4, label="start")  # fmt: skip
    ax.scatter(
        p[-1, :, 0],
        p[-1, :, 1],
        marker="s",
        s=22 * _marker_scale(run.n),
        color="tab:red",
        zorder=4,
        label="end",
    )
    ax.set(xlabel="x [m]", ylabel="y [m]", title=f"Top view: {run.label}")
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, alpha=0.3)
    _legend(ax, outside=True)
    return fig


def view_3d(run: RunData) -> Figure:
    """Trajectories and formation snapshots in 3D (spatial runs)."""
    fig = _figure((8, 7))
    ax: Any = fig.add_subplot(projection="3d")
    p, ref = run.positions_m, run.reference_m
    colours = _drone_colours(run.n)
    for i in range(run.n):
        ax.plot(*ref[:, i].T, color="0.6", lw=0.8, ls="--", label="reference path" if i == 0 else None)
        label = f"drone {i}" if run.n <= PER_DRONE_MAX else ("drone paths" if i == 0 else None)
        ax.plot(*p[:, i].T, color=colours[i], lw=1.2, label=label)
    edges = formation_edges(run.offsets_m)
    for j, tj in zip(*_snapshot_indices(run), strict=True):
        shade = colormaps["Greys"](0.45 + 0.55 * j / max(1, run.t_s.shape[0] - 1))
        for a, b in edges:
            ax.plot(*np.stack([p[j, a], p[j, b]]).T, color=shade, lw=1.0)
        ax.scatter(*p[j].T, color=shade, s=12 * _marker_scale(run.n), label=f"formation at t = {tj:.3g} s")
    ax.scatter(
        *p[0].T,
        marker="o",
        s=28 * _marker_scale(run.n),
        facecolors="none",
        edgecolors="tab:green",
        label="start",
    )
    ax.scatter(*p[-1].T, marker="s", s=22 * _marker_scale(run.n), color="tab:red", label="end")
    _equal_3d(ax, np.concatenate([p.reshape(-1, 3), ref.reshape(-1, 3)]))
    ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]", title=f"3D view: {run.label}")
    _legend(ax, outside=True)
    return fig


def tracking_error(run: RunData) -> Figure:
    """Max and median over drones of the tracking error, log scale."""
    err = tracking_errors(run)
    fig = _figure((8, 4.5))
    ax = fig.subplots()
    label = "max over drones" if run.n > 1 else "drone 0"
    ax.semilogy(run.t_s, _loggable(err.max(axis=1)), color="tab:red", label=label)
    if run.n > 1:
        ax.semilogy(run.t_s, _loggable(np.median(err, axis=1)), color="tab:blue", ls="--",
                    label="median over drones")  # fmt: skip
    ax.set(xlabel="time t [s]", ylabel="tracking error ||p_i - p*_i|| [m]",
           title=f"Tracking error: {run.label}")  # fmt: skip
    ax.grid(True, which="both", alpha=0.3)
    _legend(ax)
    return fig


def separation(run: RunData) -> Figure:
    """Smallest distance between two drones at every sample, with d_min."""
    fig = _figure((8, 4.5))
    ax = fig.subplots()
    ax.plot(run.t_s, min_separations(run), color="tab:blue", label="min distance between two drones")
    if run.d_min_m is not None:
        ax.axhline(run.d_min_m, color="tab:red", ls="--", zorder=1.5, label=f"d_min = {run.d_min_m:g} m")
    ax.set_ylim(bottom=0.0)
    ax.set(xlabel="time t [s]", ylabel="minimum separation [m]", title=f"Separation: {run.label}")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    return fig


def speeds(run: RunData) -> Figure:
    """Command speeds (held over each step) with v_max."""
    speed = np.linalg.norm(run.commands_mps, axis=-1)  # (T-1, n)
    t = run.t_s
    fig = _figure((8, 4.5))
    ax = fig.subplots()
    if run.n <= PER_DRONE_MAX:
        colours = _drone_colours(run.n)
        for i in range(run.n):
            ax.stairs(speed[:, i], t, color=colours[i], lw=1.0, baseline=None, label=f"drone {i}")
    else:
        ax.stairs(speed.max(axis=1), t, color="tab:red", baseline=None, label="max over drones")
        ax.stairs(np.median(speed, axis=1), t, color="tab:blue", baseline=None, label="median over drones")
        ax.stairs(speed.min(axis=1), t, color="tab:green", baseline=None, label="min over drones")
    if run.v_max_mps is not None:
        ax.axhline(run.v_max_mps, color="k", ls="--", zorder=1.5, label=f"v_max = {run.v_max_mps:g} m/s")
    top = max(float(speed.max()), run.v_max_mps or 0.0)
    ax.set_ylim(0.0, 1.25 * top if top > 0 else 1.0)  # headroom for the legend above the v_max line
    ax.set(xlabel="time t [s]", ylabel="speed ||u_i|| [m/s]", title=f"Command speeds: {run.label}")
    ax.grid(True, alpha=0.3)
    _legend(ax, outside=run.n <= PER_DRONE_MAX)
    return fig


def scale(run: RunData) -> Figure:
    """Best-fit scale of the drones' positions and the reference's scale."""
    fig = _figure((8, 4.5))
    ax = fig.subplots()
    rel = " (relative to the start)" if run.scale_is_relative else ""
    ax.plot(run.t_s, fitted_scales(run, run.positions_m), color="tab:blue", label="best fit of the drones")
    ref = run.scale_ref if run.scale_ref is not None else fitted_scales(run, run.reference_m)
    ax.plot(run.t_s, ref, color="k", ls="--", label="reference")
    ax.set(xlabel="time t [s]", ylabel=f"formation scale s{rel}", title=f"Scale: {run.label}")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    return fig


def animate_run(run: RunData, path: str | Path, *, max_frames: int = 80, fps: int = 12,
                trail_s: float = 3.0) -> Path:  # fmt: skip
    """Write a GIF of the flight (top view; 3D for spatial runs) with trails and the reference.

    At most ``max_frames`` frames evenly spaced in time, shown at ``fps`` frames per second.
    """
    from PIL import Image  # pillow: a dependency of matplotlib, listed in the plot extra

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    p, ref, t = run.positions_m, run.reference_m, run.t_s
    frames = np.unique(np.linspace(0, t.shape[0] - 1, min(max_frames, t.shape[0])).round().astype(int))
    trail = max(1, int(round(trail_s / float(t[1] - t[0]))))
    colours = _drone_colours(run.n)
    edges = formation_edges(run.offsets_m)
    spatial = run.dim == 3
    d = 3 if spatial else 2
    legend_in = 2.0  # the legend sits right of the axes, off the flight
    width, height = (6.0 + legend_in, 5.6) if spatial else _plan_size(run, 6.0, legend_in, 3.0)
    fig = Figure(figsize=(width, height), dpi=96)  # fixed margins: no layout engine per frame
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.8 / width, right=1.0 - (legend_in + 0.1) / width, bottom=0.65 / height,
                        top=1.0 - 0.65 / height)  # fmt: skip
    ax: Any = fig.add_subplot(projection="3d") if spatial else fig.add_subplot()
    lo = np.minimum(p.min(axis=(0, 1)), ref.min(axis=(0, 1)))[:d]
    hi = np.maximum(p.max(axis=(0, 1)), ref.max(axis=(0, 1)))[:d]
    if spatial:
        _equal_3d(ax, np.stack([lo, hi]))
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
    else:
        _draw_obstacles(ax, run)
        pad = 0.08 * float((hi - lo).max()) + 0.5
        ax.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad), xlabel="x [m]",
               ylabel="y [m]")  # fmt: skip
        ax.set_aspect("equal", adjustable="box")
        ax.grid(True, alpha=0.3)
    trails = [ax.plot(*p[:1, i, :d].T, color=colours[i], lw=1.0, alpha=0.7)[0] for i in range(run.n)]
    links = [ax.plot(*np.zeros((d, 2)), color="0.4", lw=0.8)[0] for _ in edges]
    ms = 6.0 * float(np.sqrt(_marker_scale(run.n)))  # marker diameter [pt]
    refs = ax.plot(*ref[0, :, :d].T, ls="none", marker="o", ms=1.4 * ms, mfc="none", mec="0.5",
                   label="reference p*_i")[0]  # fmt: skip
    drones = ax.plot(*p[0, :, :d].T, ls="none", marker="o", ms=ms, color="tab:blue", label="drones")[0]
    trails[0].set_label(f"last {trail_s:g} s")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small", borderaxespad=0.0)
    images = []
    for j in frames.tolist():
        start = max(0, j - trail)
        for i, line in enumerate(trails):
            _set_data(line, p[start : j + 1, i, :d], spatial)
        for (a, b), line in zip(edges, links, strict=True):
            _set_data(line, p[j, [a, b], :d], spatial)
        _set_data(refs, ref[j, :, :d], spatial)
        _set_data(drones, p[j, :, :d], spatial)
        ax.set_title(f"{run.label}\nt = {t[j]:6.2f} s", fontsize="medium")
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())  # type: ignore[attr-defined]
        images.append(Image.fromarray(rgba[..., :3].copy()))
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0)
    return path


# ---- several runs --------------------------------------------------------------------------
def compare_runs(runs: Sequence[RunData], path: str | Path, labels: Sequence[str] | None = None) -> Path:
    """One figure: tracking error (log), minimum separation and maximum speed of every run."""
    labels = [r.label for r in runs] if labels is None else list(labels)
    fig = _figure((9, 10))
    axes = fig.subplots(3, 1, sharex=True)
    colours = colormaps["tab10"]
    for k, (run, label) in enumerate(zip(runs, labels, strict=True)):
        style = {"color": colours(k % 10), "ls": LINESTYLES[k % len(LINESTYLES)], "label": label}
        axes[0].semilogy(run.t_s, _loggable(tracking_errors(run).max(axis=1)), **style)
        if run.n >= 2:
            axes[1].plot(run.t_s, min_separations(run), **style)
        speed = np.linalg.norm(run.commands_mps, axis=-1).max(axis=1)
        axes[2].stairs(speed, run.t_s, baseline=None, **style)
    for ax, key, unit, name in ((axes[1], "d_min", "m", "d_min"), (axes[2], "v_max", "m/s", "v_max")):
        values = sorted({v for v in (r.d_min_m if key == "d_min" else r.v_max_mps for r in runs) if v})
        for v in values:
            ax.axhline(v, color="k", ls="--", lw=0.9, zorder=1.5, label=f"{name} = {v:g} {unit}")
        ax.set_ylim(bottom=0.0)
    axes[0].set(ylabel="max tracking error [m]", title="Comparison of runs")
    axes[1].set(ylabel="min separation [m]")
    axes[2].set(ylabel="max speed ||u_i|| [m/s]", xlabel="time t [s]")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        _legend(ax)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(
        path, dpi=DPI, bbox_inches="tight", metadata={"Software": "mpcform", "Description": "; ".join(labels)}
    )
    return path


# ---- series -------------------------------------------------------------------------------
def tracking_errors(run: RunData) -> Array:
    """``||p_i - p*_i||`` [m], (T, n)."""
    return np.asarray(np.linalg.norm(run.positions_m - run.reference_m, axis=-1))


def min_separations(run: RunData) -> Array:
    """Smallest distance between two drones at every sample [m], (T,)."""
    return np.array([min_pair_distance(p) for p in run.positions_m])


def fitted_scales(run: RunData, positions_m: Array) -> Array:
    """Best-fit (Umeyama) scale of ``positions_m`` (T, n, d) over the run's offsets, (T,)."""
    tpl = Template(run.offsets_m - run.offsets_m.mean(axis=0))
    return np.array([fit_formation(tpl, p).state.scale for p in positions_m])


def formation_edges(offsets_m: Array) -> list[tuple[int, int]]:
    """Edges of the minimum spanning tree of the template offsets (draws any shape's skeleton)."""
    n = offsets_m.shape[0]
    if n < 2:
        return []
    dist = squareform(pdist(offsets_m)) + 1e-12 * (1 - np.eye(n))  # keep coincident points linked
    tree = minimum_spanning_tree(dist).tocoo()
    return sorted((int(min(a, b)), int(max(a, b))) for a, b in zip(tree.row, tree.col, strict=True))


# ---- helpers ------------------------------------------------------------------------------
def _figure(size_in: tuple[float, float]) -> Figure:
    fig = Figure(figsize=size_in, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _snapshot_indices(run: RunData) -> tuple[Array, Array]:
    idx = np.unique(np.linspace(0, run.t_s.shape[0] - 1, SNAPSHOTS).round().astype(int))
    return idx, run.t_s[idx]


def _draw_formation(ax: Axes, xy: Array, edges: list[tuple[int, int]], colour: Any, label: str) -> None:
    for a, b in edges:
        ax.plot(xy[[a, b], 0], xy[[a, b], 1], color=colour, lw=1.0, zorder=3)
    ax.scatter(xy[:, 0], xy[:, 1], color=colour, s=14 * _marker_scale(xy.shape[0]), zorder=3, label=label)


def _draw_obstacles(ax: Axes, run: RunData) -> None:
    d_min = run.d_min_m
    for k, row in enumerate(run.obstacles):
        centre, radius, clearance = row[:2], float(row[run.dim]), float(row[run.dim + 1])
        if not np.isfinite(clearance):
            clearance = 0.5 * d_min if d_min is not None else 0.0
        ax.add_patch(Circle(tuple(centre), radius, color="0.75", zorder=1,
                            label="obstacle" if k == 0 else None))  # fmt: skip
        if clearance > 0:
            ax.add_patch(Circle(tuple(centre), radius + clearance, fill=False, ls=":", color="0.4",
                                zorder=1, label="obstacle + clearance" if k == 0 else None))  # fmt: skip


def _plan_size(
    run: RunData, width_in: float = 6.5, legend_in: float = 2.8, min_height_in: float = 4.2
) -> tuple[float, float]:
    """Figure size for an equal-aspect x-y plot of the run: the height follows the data."""
    xy = np.concatenate([run.positions_m[..., :2].reshape(-1, 2), run.reference_m[..., :2].reshape(-1, 2)])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    for row in run.obstacles:
        reach = float(row[run.dim]) + (float(row[run.dim + 1]) if np.isfinite(row[run.dim + 1]) else 0.0)
        lo, hi = np.minimum(lo, row[:2] - reach), np.maximum(hi, row[:2] + reach)
    span = np.maximum(hi - lo, 1.0)
    height = float(np.clip(width_in * span[1] / span[0] + 1.3, min_height_in, 9.0))
    return width_in + legend_in, height


def _loggable(values: Array) -> Array:
    """``values`` with those below :data:`LOG_FLOOR_M` (zero at an exact start) as NaN: gaps, not cliffs."""
    return np.where(values >= LOG_FLOOR_M, values, np.nan)


def _marker_scale(n: int) -> float:
    """Smaller markers for large swarms (1 up to 20 drones, 0.3 at 100)."""
    return float(min(1.0, max(0.3, 20.0 / max(n, 1))))


def _drone_colours(n: int) -> list[Any]:
    """Distinct colours without grey (the formation snapshots are grey) up to 9, else viridis."""
    if n <= len(DRONE_COLOURS):
        return list(DRONE_COLOURS[:n])
    return [colormaps["viridis"](i / max(1, n - 1)) for i in range(n)]


def _legend(ax: Any, outside: bool = False) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    if outside:
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small", borderaxespad=0.0)
    else:
        ax.legend(loc="best", fontsize="small")


def _equal_3d(ax: Any, points: Array) -> None:
    lo, hi = points.min(axis=0), points.max(axis=0)
    mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.5) * 1.05
    ax.set(xlim=(mid[0] - half, mid[0] + half), ylim=(mid[1] - half, mid[1] + half),
           zlim=(mid[2] - half, mid[2] + half))  # fmt: skip
    ax.set_box_aspect((1, 1, 1))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))


def _set_data(line: Any, xyz: Array, spatial: bool) -> None:
    line.set_data(xyz[:, 0], xyz[:, 1])
    if spatial:
        line.set_3d_properties(xyz[:, 2])


def _save(fig: Figure, path: Path, run: RunData) -> Path:
    prov = run.summary.get("provenance") or {}
    metadata = {
        "Title": f"{path.stem}: {run.label}",
        "Software": f"mpcform {prov.get('mpcform')}",
        "Description": f"scenario {run.name}, sha256 {prov.get('scenario_sha256')}, seed {prov.get('seed')}",
        "Source": str(run.directory),
    }
    fig.savefig(path, dpi=DPI, bbox_inches="tight", metadata=metadata)  # nothing clipped
    return path
