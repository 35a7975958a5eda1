"""Figures of runs (matplotlib, Agg canvas; ``pip install "mpcform[plot]"``).

Imported only when plots are asked for (never by ``mpcform/__init__``). Figures are built
with matplotlib's object API on an Agg canvas, never through pyplot: no window opens, no
global backend is switched, and nothing stays in pyplot's figure registry. Every figure is drawn
from a :class:`~mpcform.outputs.rundata.RunData` (a run in memory or read back from its
directory) with the series of :mod:`mpcform.sim.metrics` and :mod:`mpcform.sim.safety`, in the
style of :mod:`mpcform.outputs.drawing` (above six drones, a min-max band and the median over
drones replace the per-drone lines):

- ``top_view.png`` and ``view_3d.png`` (spatial runs: x-y, x-z, y-z projections): see
  :mod:`mpcform.outputs.plan_views`;
- ``tracking_error.png``: ``||p_i - p*_i||`` [m] over drones, log scale;
- ``separation.png``: minimum distance between two drones [m], d_min, the closest moment marked;
  for a plant run also the flown minimum over the dense true path, its lowest point marked;
- ``speed.png``: command speeds ``||u_i||`` [m/s] (zero-order hold) with v_max; for a plant run
  also the flown speeds ``||v_i||`` of the dense true path, their peak marked;
- ``clearance.png`` (runs with obstacles): distance of the drones to each obstacle's surface
  along the segments [m] against the required clearance;
- ``scale.png``: best-fit scale of the positions (Umeyama) and the reference's scale, drawn only
  where the drones hold the template's shape (a permuted or mirrored start has no scale), and the
  drones' own estimates ``s_hat_i`` when the run recorded them (consensus);
- :func:`compare_runs`: tracking error, separation and speed of several runs on one figure.

PNG files carry the run's provenance (scenario, hash, seed, versions) in their metadata.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.kinematics import fit_formation
from mpcform.formation.template import Template
from mpcform.outputs.drawing import (
    CLOSEST_COLOUR,
    LIMIT_STYLE,
    MEDIAN_COLOUR,
    PER_DRONE_MAX,
    closest_pair,
    envelope,
    per_drone_style,
)
from mpcform.outputs.files import FIGURE_DPI, FIGURE_FORMATS
from mpcform.outputs.flown import flown_separation, flown_speeds
from mpcform.outputs.plan_views import new_figure, top_view, view_3d
from mpcform.outputs.rundata import RunData
from mpcform.sim.metrics import command_speeds_mps, min_separations_m, tracking_errors_m
from mpcform.sim.safety import obstacle_distances_along
from mpcform.world.shapes.shape_set import ShapeSet

FIGURE_FILES = (
    "top_view.png",
    "view_3d.png",
    "tracking_error.png",
    "separation.png",
    "speed.png",
    "clearance.png",
    "scale.png",
)
LINESTYLES = ("-", "--", ":", "-.")  # runs of a comparison: overlapping curves stay visible
LOG_FLOOR_M = 1e-6  # tracking errors below this (exact starts, rounding) are not drawn on the log axis
AXIS_HEADROOM = 1.1  # a time-series axis ends at most 10 % above what it must show
SHAPE_TOL = 0.2  # relative RMS residual above which the drones do not hold the template's shape
SERIES_SIZE_IN = (8.0, 4.2)
ESTIMATE_GID = "scale-estimate"  # a drone's (or the median) scale estimate s_hat_i in scale.png
LEADER_GID = "scale-leader"  # a leader's scale estimate, starred
LEADER_STARS = 9  # stars along a leader's estimate
FIT_UNDER_ESTIMATES: dict[str, Any] = {"color": "0.55", "lw": 2.6, "alpha": 0.7, "zorder": 1.5}
DPI = FIGURE_DPI


def plot_run(run: RunData, out_dir: str | Path, fmt: str = "png", dpi: int = DPI) -> list[Path]:
    """Write the figures of ``run`` into ``out_dir`` (created) as ``fmt`` (:data:`FIGURE_FORMATS`)
    at ``dpi``; returns the paths written."""
    if fmt not in FIGURE_FORMATS:
        raise ValidationError("format", f"expected one of {', '.join(FIGURE_FORMATS)}, got {fmt!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures: list[tuple[str, Figure]] = [("top_view.png", top_view(run))]
    if run.dim == 3:
        figures.append(("view_3d.png", view_3d(run)))
    figures += [("tracking_error.png", tracking_error(run)), ("speed.png", speeds(run))]
    if run.formation.obstacles:
        figures.append(("clearance.png", clearance(run)))
    if run.n >= 2:  # one drone has neither separation nor scale
        figures += [("separation.png", separation(run)), ("scale.png", scale(run))]
    return [save_figure(fig, (out / name).with_suffix(f".{fmt}"), run, dpi) for name, fig in figures]


# ---- single runs ------------------------------------------------------------------------
def tracking_error(run: RunData) -> Figure:
    """Tracking error of every drone (up to six) or its min-max band and median, log scale."""
    err, t = _loggable(tracking_errors_m(run.trajectory)), run.trajectory.t_s
    fig, ax = _series_axes()
    if run.n <= PER_DRONE_MAX:
        for i in range(run.n):
            ax.plot(t, err[:, i], label=f"drone {i}", **per_drone_style(i))
    else:
        envelope(ax, t, err, MEDIAN_COLOUR, "tracking error")
    ax.set_yscale("log")
    ax.set_ylim(bottom=max(ax.get_ylim()[0], LOG_FLOOR_M))  # rounding-level errors squash the rest
    _finish(ax, run, "Tracking error", "tracking error ||p_i - p*_i|| [m]")
    return fig


def separation(run: RunData) -> Figure:
    """Smallest distance between two drones at every sample, d_min, and the closest moment."""
    fig, ax = _series_axes()
    sep, t = min_separations_m(run.trajectory), run.trajectory.t_s
    ax.plot(t, sep, color=MEDIAN_COLOUR, lw=1.4, label="min distance between two drones")
    if run.d_min_m is not None:
        ax.axhline(run.d_min_m, label=f"d_min = {run.d_min_m:g} m", **LIMIT_STYLE)
    k, i, j, dist = closest_pair(run.trajectory.positions_m)
    ax.plot(
        t[k],
        dist,
        "o",
        color=CLOSEST_COLOUR,
        ms=7,
        zorder=5,
        label=f"closest: drones {i}-{j}, {dist:.3g} m at t = {t[k]:.3g} s",
    )
    highest = max(float(sep.max()), flown_separation(ax, run))  # a plant run's, dense
    ax.set_ylim(0.0, AXIS_HEADROOM * max(highest, run.d_min_m or 0.0))
    _finish(ax, run, "Separation", "minimum separation [m]")
    return fig


def speeds(run: RunData) -> Figure:
    """Command speeds (held over each step) per drone or as an envelope, with v_max."""
    speed, t = command_speeds_mps(run.trajectory), run.trajectory.t_s  # (T-1, n), (T,)
    fig, ax = _series_axes()
    if run.n <= PER_DRONE_MAX:
        for i in range(run.n):
            ax.stairs(speed[:, i], t, baseline=None, label=f"drone {i}", **per_drone_style(i))
    else:
        envelope(ax, t, speed, MEDIAN_COLOUR, "speed", stairs=True)
    peak = max(float(speed.max()), flown_speeds(ax, run))  # a plant run's, dense
    top = speed_axis_top(peak, run.v_max_mps)
    v_max = run.v_max_mps
    if v_max is not None and v_max <= top:
        ax.axhline(v_max, label=f"v_max = {v_max:g} m/s", **LIMIT_STYLE)
    elif v_max is not None:
        ax.text(
            0.99,
            0.97,
            f"v_max = {v_max:g} m/s (off scale: {v_max / peak:.3g}x the peak)",
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize="small",
            color="tab:red",
        )
    ax.set_ylim(0.0, top)
    flown_too = " (solid) and flown (dotted)" if run.flown is not None and run.n <= PER_DRONE_MAX else ""
    _finish(ax, run, f"Command speeds{flown_too}", "speed ||u_i|| [m/s]")
    return fig


def speed_axis_top(data_max: float, v_max: float | None) -> float:
    """Upper end of a speed axis: 10 % above the data's peak, or above v_max when v_max is within
    twice the peak (otherwise v_max is written, not drawn)."""
    top = data_max
    if v_max is not None and v_max <= 2.0 * data_max:
        top = max(top, v_max)
    return AXIS_HEADROOM * top if top > 0 else 1.0


def clearance(run: RunData) -> Figure:
    """Distance [m] of the drones to each obstacle's surface along the segments (min over drones),
    against its required clearance (default d_min / 2)."""
    traj = run.trajectory
    obstacles = run.obstacles  # clearances resolved (older runs' NaN: d_min / 2)
    dist = obstacle_distances_along(traj.positions_m, obstacles)  # (T - 1, n, m) to the cores
    rounding = ShapeSet(obstacles, run.dim).rounding_m  # the cores grown by it: the surfaces
    t_mid = 0.5 * (traj.t_s[1:] + traj.t_s[:-1])  # one value per segment, at its middle
    fig, ax = _series_axes()
    colours = colormaps["tab10"]
    required = [ob.resolved_clearance_m for ob in obstacles]
    for k in range(len(obstacles)):
        surface = dist[:, :, k].min(axis=1) - rounding[k]
        tag = f"obstacle {k}" if len(obstacles) > 1 else "obstacle"
        ax.plot(
            t_mid,
            surface,
            color=colours(k % 10),
            ls=LINESTYLES[k % len(LINESTYLES)],
            lw=1.4,
            label=f"{tag}: closest drone, min {surface.min():.3g} m",
        )
        m = int(np.argmin(surface))
        ax.plot(t_mid[m], surface[m], "o", color=CLOSEST_COLOUR, ms=6, zorder=5)
        if len(set(required)) > 1:
            ax.axhline(required[k], color=colours(k % 10), ls="--", lw=1.0, label=f"{tag}: required")
    if len(set(required)) == 1:
        ax.axhline(required[0], label=f"required clearance {required[0]:.3g} m", **LIMIT_STYLE)
    ax.set_ylim(bottom=0.0)
    _finish(ax, run, "Obstacle clearance", "distance to the obstacle's surface [m]")
    return fig


def scale(run: RunData) -> Figure:
    """Best-fit scale of the drones' positions (where they hold the template's shape), the
    reference's scale and, for a consensus run, each drone's own estimate ``s_hat_i`` (seed eq. 20):
    one line per drone up to six drones, else their min-max band and median, the leaders starred."""
    traj, formation = run.trajectory, run.formation
    fig, ax = _series_axes()
    rel = " (relative to the start)" if formation.scale_is_relative else ""
    estimates = traj.scale_estimates
    drawn = estimates is not None and not formation.scale_is_relative  # absolute, like s_hat_i
    fitted, shaped = fitted_scales_in_shape(formation.offsets_m, traj.positions_m)
    fit_style = FIT_UNDER_ESTIMATES if drawn else {"color": MEDIAN_COLOUR, "lw": 1.4}
    ax.plot(
        traj.t_s, np.where(shaped, fitted, np.nan), label="best fit of the drones' positions", **fit_style
    )
    ref = formation.scale_ref
    if ref is None:
        ref = fitted_scales_in_shape(formation.offsets_m, traj.reference_m)[0]
    ax.plot(traj.t_s, ref, label="reference s*(t)", **{**LIMIT_STYLE, "color": "k", "zorder": 3})
    notes = []
    if not shaped.all():
        t_in = traj.t_s[shaped]
        for k, (a, b) in enumerate(_runs(~shaped)):
            ax.axvspan(
                traj.t_s[a],
                traj.t_s[b],
                color="0.85",
                lw=0,
                zorder=0,
                label="not in the template's shape" if k == 0 else None,
            )
        since = f"; in shape from t = {t_in[0]:.3g} s" if t_in.size else ""
        notes.append(f"not drawn while the drones do not hold the template's shape{since}")
    if estimates is not None and drawn:
        draw_scale_estimates(ax, traj.t_s, estimates, formation.leaders)
    elif estimates is not None:
        notes.append("estimates s_hat_i not drawn: they need the template's scale (formation.npz)")
    _finish(ax, run, "Scale", f"formation scale s{rel}")
    if notes:  # under the time axis, off the curves
        ax.set_xlabel("\n".join([ax.get_xlabel(), *notes]), gid="scale-note")
    return fig


def draw_scale_estimates(ax: Any, t_s: Array, estimates: Array, leaders: Sequence[int]) -> None:
    """The drones' scale estimates (T, n): a line per drone (gid :data:`ESTIMATE_GID`) up to
    :data:`PER_DRONE_MAX` drones, else the min-max band (gid ``envelope``) and the median (gid
    :data:`ESTIMATE_GID`); every leader's estimate starred (gid :data:`LEADER_GID`)."""
    n = estimates.shape[1]
    if n <= PER_DRONE_MAX:
        for i in range(n):
            style = per_drone_style(i)
            ax.plot(t_s, estimates[:, i], label=f"drone {i}: s_hat_{i}", gid=ESTIMATE_GID, **style)
    else:
        envelope(ax, t_s, estimates, MEDIAN_COLOUR, "estimates s_hat_i")
        ax.lines[-1].set_gid(ESTIMATE_GID)
    stars = np.unique(np.linspace(0, t_s.shape[0] - 1, LEADER_STARS + 2)[1:-1].round().astype(int))
    names = ", ".join(map(str, leaders))
    label = f"leader {names} (sees s*)" if len(leaders) == 1 else f"leaders {names} (see s*)"
    for k, i in enumerate(leaders):
        ax.plot(
            t_s,
            estimates[:, i],
            ls="-" if n > PER_DRONE_MAX else "none",
            color="goldenrod",
            lw=1.0,
            marker="*",
            markevery=stars,
            ms=11,
            mfc="gold",
            mec="k",
            mew=0.6,
            zorder=4,
            gid=LEADER_GID,
            label=label if k == 0 else None,
        )


def fitted_scales_in_shape(offsets_m: Array, positions_m: Array) -> tuple[Array, Array]:
    """Best-fit (Umeyama) scale at every sample and whether the drones hold the template's shape
    there (RMS residual at most :data:`SHAPE_TOL` of the fitted size, the fit identifiable)."""
    template = Template(offsets_m - offsets_m.mean(axis=0))
    size = float(np.sqrt((template.offsets**2).sum(axis=1).mean()))
    fits = [fit_formation(template, p) for p in positions_m]
    scales = np.array([f.state.scale for f in fits])
    shaped = np.array(
        [f.scale_identifiable and f.residual_rms_m <= SHAPE_TOL * f.state.scale * size for f in fits]
    )
    return scales, shaped


# ---- several runs --------------------------------------------------------------------------
def compare_runs(runs: Sequence[RunData], path: str | Path, labels: Sequence[str] | None = None) -> Path:
    """One figure: tracking error (log), minimum separation and maximum speed of every run."""
    labels = [r.label for r in runs] if labels is None else list(labels)
    fig = new_figure((9, 10))
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


def _runs(mask: Array) -> list[tuple[int, int]]:
    """``(first, last)`` sample index of each run of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True))


# ---- helpers ------------------------------------------------------------------------------
def _series_axes() -> tuple[Figure, Any]:
    fig = new_figure(SERIES_SIZE_IN)
    return fig, fig.subplots()


def _finish(ax: Any, run: RunData, title: str, ylabel: str) -> None:
    ax.set(xlabel="time t [s]", ylabel=ylabel, xlim=(run.trajectory.t_s[0], run.trajectory.t_s[-1]))
    ax.set_title(f"{title}: {run.label}", fontsize="medium")
    ax.grid(True, which="both", alpha=0.3)
    _legend(ax)


def _loggable(values: Array) -> Array:
    """``values`` with those below :data:`LOG_FLOOR_M` (zero at an exact start) as NaN: gaps, not cliffs."""
    return np.where(values >= LOG_FLOOR_M, values, np.nan)


def _legend(ax: Any) -> None:
    handles, _ = ax.get_legend_handles_labels()
    if handles:
        ax.legend(loc="best", fontsize="small", framealpha=0.9)


def save_figure(fig: Figure, path: Path, run: RunData, dpi: int = DPI) -> Path:
    """Write ``fig`` in the format of ``path``'s suffix (PNG, PDF or SVG) with the run's provenance
    in its metadata."""
    prov = run.summary.get("provenance") or {}
    software = f"mpcform {prov.get('mpcform')}"
    described = f"scenario {run.name}, sha256 {prov.get('scenario_sha256')}, seed {prov.get('seed')}"
    metadata = {"Title": f"{path.stem}: {run.label}"} | {  # each format's own keys
        ".png": {"Software": software, "Description": described, "Source": str(run.directory)},
        ".pdf": {"Creator": software, "Subject": described},
        ".svg": {"Creator": software, "Description": described, "Source": str(run.directory)},
    }[path.suffix]
    fig.savefig(path, dpi=dpi, bbox_inches="tight", metadata=metadata)  # nothing clipped
    return path
