"""Figures of runs (matplotlib, Agg canvas; ``pip install "mpcform[plot]"``).

Imported only when plots are asked for (never by ``mpcform/__init__``). Figures are built
with matplotlib's object API on an Agg canvas, never through pyplot: no window opens, no
global backend is switched, and nothing stays in pyplot's figure registry. Every figure is drawn
from a :class:`~mpcform.outputs.rundata.RunData` (a run in memory or read back from its
directory) with the series of :mod:`mpcform.sim.metrics`:

- ``top_view.png``: trajectories in the x-y plane, formation snapshots (drones joined by the
  template's minimum spanning tree), start and end, reference paths, obstacles;
- ``view_3d.png`` (spatial runs): the same in 3D;
- ``tracking_error.png``: max and median over drones of ``||p_i - p*_i||`` [m], log scale;
- ``separation.png``: minimum distance between two drones [m] with the d_min line;
- ``speed.png``: command speeds ``||u_i||`` [m/s] (zero-order hold) with the v_max line;
- ``scale.png``: best-fit scale of the positions (Umeyama) and the reference's scale;
- :func:`compare_runs`: tracking error, separation and speed of several runs on one figure.

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

from mpcform._validate import Array
from mpcform.outputs.drawing import (
    PER_DRONE_MAX,
    draw_obstacles,
    drone_colours,
    equal_3d,
    formation_edges,
    marker_scale,
    plan_size,
)
from mpcform.outputs.rundata import RunData
from mpcform.sim.metrics import command_speeds_mps, fitted_scales, min_separations_m, tracking_errors_m

FIGURE_FILES = ("top_view.png", "view_3d.png", "tracking_error.png", "separation.png", "speed.png",
                "scale.png")  # fmt: skip
SNAPSHOTS = 5
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
    fig = _figure(plan_size(run))
    ax = fig.subplots()
    draw_obstacles(ax, run)
    p, ref = run.trajectory.positions_m, run.trajectory.reference_m
    colours = drone_colours(run.n)
    for i in range(run.n):
        ax.plot(ref[:, i, 0], ref[:, i, 1], color="0.6", lw=0.8, ls="--",
                label="reference path" if i == 0 else None)  # fmt: skip
        label = f"drone {i}" if run.n <= PER_DRONE_MAX else ("drone paths" if i == 0 else None)
        ax.plot(p[:, i, 0], p[:, i, 1], color=colours[i], lw=1.2, label=label)
    edges = formation_edges(run.formation.offsets_m)
    for j, tj in zip(*_snapshot_indices(run), strict=True):
        shade = colormaps["Greys"](0.45 + 0.55 * j / max(1, run.trajectory.t_s.shape[0] - 1))
        _draw_formation(ax, p[j, :, :2], edges, shade, f"formation at t = {tj:.3g} s")
    size = marker_scale(run.n)
    ax.scatter(p[0, :, 0], p[0, :, 1], marker="o", s=28 * size, facecolors="none", edgecolors="tab:green",
               zorder=4, label="start")  # fmt: skip
    ax.scatter(p[-1, :, 0], p[-1, :, 1], marker="s", s=22 * size, color="tab:red", zorder=4, label="end")
    ax.set(xlabel="x [m]", ylabel="y [m]", title=f"Top view: {run.label}")
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, alpha=0.3)
    _legend(ax, outside=True)
    return fig


def view_3d(run: RunData) -> Figure:
    """Trajectories and formation snapshots in 3D (spatial runs)."""
    fig = _figure((8, 7))
    ax: Any = fig.add_subplot(projection="3d")
    p, ref = run.trajectory.positions_m, run.trajectory.reference_m
    colours = drone_colours(run.n)
    for i in range(run.n):
        ax.plot(*ref[:, i].T, color="0.6", lw=0.8, ls="--", label="reference path" if i == 0 else None)
        label = f"drone {i}" if run.n <= PER_DRONE_MAX else ("drone paths" if i == 0 else None)
        ax.plot(*p[:, i].T, color=colours[i], lw=1.2, label=label)
    edges = formation_edges(run.formation.offsets_m)
    size = marker_scale(run.n)
    for j, tj in zip(*_snapshot_indices(run), strict=True):
        shade = colormaps["Greys"](0.45 + 0.55 * j / max(1, run.trajectory.t_s.shape[0] - 1))
        for a, b in edges:
            ax.plot(*np.stack([p[j, a], p[j, b]]).T, color=shade, lw=1.0)
        ax.scatter(*p[j].T, color=shade, s=12 * size, label=f"formation at t = {tj:.3g} s")
    ax.scatter(*p[0].T, marker="o", s=28 * size, facecolors="none", edgecolors="tab:green", label="start")
    ax.scatter(*p[-1].T, marker="s", s=22 * size, color="tab:red", label="end")
    equal_3d(ax, np.concatenate([p.reshape(-1, 3), ref.reshape(-1, 3)]))
    ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]", title=f"3D view: {run.label}")
    _legend(ax, outside=True)
    return fig


def tracking_error(run: RunData) -> Figure:
    """Max and median over drones of the tracking error, log scale."""
    err, t = tracking_errors_m(run.trajectory), run.trajectory.t_s
    fig = _figure((8, 4.5))
    ax = fig.subplots()
    label = "max over drones" if run.n > 1 else "drone 0"
    ax.semilogy(t, _loggable(err.max(axis=1)), color="tab:red", label=label)
    if run.n > 1:
        ax.semilogy(t, _loggable(np.median(err, axis=1)), color="tab:blue", ls="--",
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
    ax.plot(run.trajectory.t_s, min_separations_m(run.trajectory), color="tab:blue",
            label="min distance between two drones")  # fmt: skip
    if run.d_min_m is not None:
        ax.axhline(run.d_min_m, color="tab:red", ls="--", zorder=1.5, label=f"d_min = {run.d_min_m:g} m")
    ax.set_ylim(bottom=0.0)
    ax.set(xlabel="time t [s]", ylabel="minimum separation [m]", title=f"Separation: {run.label}")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    return fig


def speeds(run: RunData) -> Figure:
    """Command speeds (held over each step) with v_max."""
    speed, t = command_speeds_mps(run.trajectory), run.trajectory.t_s  # (T-1, n), (T,)
    fig = _figure((8, 4.5))
    ax = fig.subplots()
    if run.n <= PER_DRONE_MAX:
        colours = drone_colours(run.n)
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
    traj, formation = run.trajectory, run.formation
    fig = _figure((8, 4.5))
    ax = fig.subplots()
    rel = " (relative to the start)" if formation.scale_is_relative else ""
    ax.plot(traj.t_s, fitted_scales(formation.offsets_m, traj.positions_m), color="tab:blue",
            label="best fit of the drones")  # fmt: skip
    ref = formation.scale_ref
    if ref is None:
        ref = fitted_scales(formation.offsets_m, traj.reference_m)
    ax.plot(traj.t_s, ref, color="k", ls="--", label="reference")
    ax.set(xlabel="time t [s]", ylabel=f"formation scale s{rel}", title=f"Scale: {run.label}")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    return fig


# ---- several runs --------------------------------------------------------------------------
def compare_runs(runs: Sequence[RunData], path: str | Path, labels: Sequence[str] | None = None) -> Path:
    """One figure: tracking error (log), minimum separation and maximum speed of every run."""
    labels = [r.label for r in runs] if labels is None else list(labels)
    fig = _figure((9, 10))
    axes = fig.subplots(3, 1, sharex=True)
    colours = colormaps["tab10"]
    for k, (run, label) in enumerate(zip(runs, labels, strict=True)):
        style = {"color": colours(k % 10), "ls": LINESTYLES[k % len(LINESTYLES)], "label": label}
        traj = run.trajectory
        axes[0].semilogy(traj.t_s, _loggable(tracking_errors_m(traj).max(axis=1)), **style)
        if run.n >= 2:
            axes[1].plot(traj.t_s, min_separations_m(traj), **style)
        axes[2].stairs(command_speeds_mps(traj).max(axis=1), traj.t_s, baseline=None, **style)
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


# ---- helpers ------------------------------------------------------------------------------
def _figure(size_in: tuple[float, float]) -> Figure:
    fig = Figure(figsize=size_in, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _snapshot_indices(run: RunData) -> tuple[Array, Array]:
    t = run.trajectory.t_s
    idx = np.unique(np.linspace(0, t.shape[0] - 1, SNAPSHOTS).round().astype(int))
    return idx, t[idx]


def _draw_formation(ax: Axes, xy: Array, edges: list[tuple[int, int]], colour: Any, label: str) -> None:
    for a, b in edges:
        ax.plot(xy[[a, b], 0], xy[[a, b], 1], color=colour, lw=1.0, zorder=3)
    ax.scatter(xy[:, 0], xy[:, 1], color=colour, s=14 * marker_scale(xy.shape[0]), zorder=3, label=label)


def _loggable(values: Array) -> Array:
    """``values`` with those below :data:`LOG_FLOOR_M` (zero at an exact start) as NaN: gaps, not cliffs."""
    return np.where(values >= LOG_FLOOR_M, values, np.nan)


def _legend(ax: Any, outside: bool = False) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    if outside:
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small", borderaxespad=0.0)
    else:
        ax.legend(loc="best", fontsize="small")


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
