"""Drawing pieces shared by the figures and the animation (matplotlib): one style, the formation's
edges, drone colours, time-coloured snapshots, envelopes, the closest pair, the communication
graph, obstacles, plan-view sizes and equal 3D axes.

Imported only when plots are asked for, like :mod:`mpcform.outputs.figures` and
:mod:`mpcform.outputs.animation`.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import offset_copy
from scipy.spatial import ConvexHull, QhullError

from mpcform._validate import Array
from mpcform.formation.geometry import closest_pair, formation_edges
from mpcform.outputs.files import plant_events
from mpcform.outputs.rundata import RunData

# ---- the one style of every figure ---------------------------------------------------------
DRONE_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")
DRONE_LINESTYLES = ("-", (0, (5, 2)), "-.", (0, (1, 1.5)), (0, (8, 2, 1, 2)), (0, (3, 3)))
"""Per-drone dash patterns: curves of drones that move alike (symmetric formations) stay visible."""
PER_DRONE_MAX = len(DRONE_COLOURS)  # up to this many drones: one line per drone, else envelopes
TIME_CMAP = ListedColormap(colormaps["plasma"](np.linspace(0.0, 0.82, 256)), name="time")
"""Snapshots coloured by time: dark blue (start) to orange (end); no pale yellow on white."""
PATH_GREY = "0.55"  # paths of a swarm above PATH_COLOURS_MAX drones
PATH_COLOURS_MAX = 20  # up to this many drones a plan's paths get a colour each: no grey tangle
REFERENCE_STYLE: dict[str, Any] = {
    "color": "k",
    "lw": 0.9,
    "ls": (0, (4, 3)),
    "zorder": 2.6,
}  # above the paths
LIMIT_STYLE: dict[str, Any] = {
    "color": "tab:red",
    "ls": "--",
    "lw": 1.1,
    "zorder": 1.5,
}  # d_min, v_max, clearance
CLOSEST_COLOUR = "crimson"
MEDIAN_COLOUR = "tab:blue"
BAND_ALPHA = 0.25
SNAPSHOTS = 4
SNAPSHOT_LABEL = "snapshot-label"  # gid of the ``t = ... s`` text beside a snapshot
FLOWN_GID = "flown"  # gid of what the drones really did (a plant run's dense true path)
WIND_GID = "wind"  # gid of the plant's mean wind arrow and its label
WIND_COLOUR = "tab:cyan"
EVENTS_GID = "plant-events"  # gid of the note of what the plant reported (contacts, floor, flips)
FLOWN_COLOUR = "tab:green"  # a swarm's flown speeds and separation (per drone: the drone's colour)
DISPLAY_SAMPLES = 3000  # a dense true path drawn with at most about this many samples


REFERENCE_PATHS_MAX = 8  # a swarm's reference paths: those of this many outline drones


def reference_subset(run: RunData, plane: tuple[int, int]) -> Array:
    """The drones whose reference paths a plan draws: all up to :data:`PER_DRONE_MAX`, else at most
    :data:`REFERENCE_PATHS_MAX` spread along the outline (convex hull) of the template in ``plane``
    (a hundred arcs would bury the formation's turn)."""
    if run.n <= PER_DRONE_MAX:
        return np.arange(run.n)
    offsets = run.formation.offsets_m[:, list(plane)]
    try:
        outline = ConvexHull(offsets).vertices
    except QhullError:  # a line of drones: its ends and the drones between
        outline = np.arange(run.n)
    pick = np.linspace(0, outline.shape[0], min(REFERENCE_PATHS_MAX, outline.shape[0]), endpoint=False)
    return np.sort(outline[pick.astype(int)])


def display_rows(samples: int, limit: int = DISPLAY_SAMPLES) -> Array:
    """Indices of at most about ``limit`` of ``samples`` evenly strided, the last included: what a
    line is drawn through (peaks and minima are taken from every sample, not these)."""
    idx = np.arange(0, samples, max(1, -(-samples // limit)))
    return idx if idx[-1] == samples - 1 else np.append(idx, samples - 1)


def skeleton_edges(run: RunData) -> list[tuple[int, int]]:
    """The edges drawn in a run's plan views: :func:`formation_edges`, except none for a swarm of
    more than :data:`PER_DRONE_MAX` drones on a truly 3-D template (a projected tangle)."""
    offsets = run.formation.offsets_m
    sv = np.linalg.svd(offsets - offsets.mean(axis=0), compute_uv=False)
    solid = sv.shape[0] >= 3 and sv[2] > 1e-9 * sv[0]
    return [] if solid and run.n > PER_DRONE_MAX else formation_edges(offsets)


def per_drone_style(i: int) -> dict[str, Any]:
    """Colour and dash pattern of drone ``i`` (``i < PER_DRONE_MAX``) in the time series."""
    return {"color": DRONE_COLOURS[i], "ls": DRONE_LINESTYLES[i], "lw": 1.3}


def drone_colours(n: int) -> list[Any]:
    """Distinct colours up to :data:`PER_DRONE_MAX` drones, else shades of one colour map."""
    if n <= len(DRONE_COLOURS):
        return list(DRONE_COLOURS[:n])
    return [colormaps["viridis"](0.1 + 0.8 * i / max(1, n - 1)) for i in range(n)]


def distinct_colours(n: int) -> list[Any]:
    """``n`` qualitative colours, the first six :data:`DRONE_COLOURS`: tab10, then tab20's light
    shades up to 20 (light blue after blue, not beside it), beyond an evenly sampled colour map."""
    if n <= 20:
        tab20 = colormaps["tab20"]
        return [tab20(2 * i if i < 10 else 2 * (i - 10) + 1) for i in range(n)]
    return [colormaps["turbo"](0.05 + 0.9 * i / (n - 1)) for i in range(n)]


def path_colours(n: int) -> list[Any]:
    """A plan view's path colours: :func:`distinct_colours` up to :data:`PATH_COLOURS_MAX` drones
    (the first six those of the time series), else one grey."""
    return distinct_colours(n) if n <= PATH_COLOURS_MAX else [PATH_GREY] * n


def marker_scale(n: int) -> float:
    """Smaller markers for large swarms (1 up to 20 drones, 0.3 at 100)."""
    return float(min(1.0, max(0.3, 20.0 / max(n, 1))))


def snapshot_indices(run: RunData, count: int = SNAPSHOTS) -> Array:
    """Sample indices of ``count`` snapshots evenly spaced in time over the part of the flight
    where the drones move (until the last command above 1 % of the peak speed): a run that
    settles early does not repeat its final shape."""
    speed = np.linalg.norm(run.trajectory.commands_mps, axis=-1).max(axis=1)  # (T - 1,)
    moving: Any = np.flatnonzero(speed > 0.01 * speed.max()) if speed.size and speed.max() > 0 else []
    last = int(moving[-1]) + 1 if len(moving) else run.trajectory.t_s.shape[0] - 1
    return np.unique(np.linspace(0, last, count).round().astype(int))


def time_colour(run: RunData) -> tuple[Any, Normalize]:
    """The colour map and normalisation of the snapshots' time (for a colour bar)."""
    t = run.trajectory.t_s
    return TIME_CMAP, Normalize(float(t[0]), float(t[-1]))


def draw_snapshot(
    ax: Axes,
    xy: Array,
    edges: list[tuple[int, int]],
    colour: Any,
    t_s: float,
    size: float,
    label: str = "text",
    anchor: int = 0,
) -> None:
    """One formation snapshot in a plane: its edges, drones and its time, ``t = ... s``, written
    beside drone ``anchor`` (``label="text"``) or as its legend entry (``"legend"``)."""
    for a, b in edges:
        ax.plot(xy[[a, b], 0], xy[[a, b], 1], color=colour, lw=1.3, zorder=3)
    ax.scatter(
        xy[:, 0],
        xy[:, 1],
        color=colour,
        s=16 * size,
        zorder=3.1,
        edgecolors="k",
        lw=0.3,
        label=f"snapshot t = {t_s:.3g} s" if label == "legend" else None,
    )
    if label == "text":  # beside drone ``anchor``, pushed outward from the snapshot's centre
        away = xy[anchor] - xy.mean(axis=0)
        away = away / norm if (norm := float(np.linalg.norm(away))) > 0 else np.array([0.0, 1.0])
        box = {"boxstyle": "round,pad=0.15", "fc": "white", "ec": colour, "alpha": 0.85}
        ax.annotate(
            f"t = {t_s:.3g} s",
            xy[anchor],
            xytext=tuple(14 * away),
            textcoords="offset points",
            ha="center",
            va="center",
            fontsize="x-small",
            zorder=5,
            gid=SNAPSHOT_LABEL,
            bbox=box,
        )


def envelope(ax: Axes, t_s: Array, values: Array, colour: Any, label: str, *, stairs: bool = False) -> None:
    """Min-max band and median over drones of ``values`` (T or T - 1, n) (``stairs``: held values)."""
    lo, mid, hi = values.min(axis=1), np.median(values, axis=1), values.max(axis=1)
    if stairs:  # a command is held over its step: repeat the last value at the end
        lo, mid, hi = (np.append(x, x[-1]) for x in (lo, mid, hi))
    ax.fill_between(
        t_s,
        lo,
        hi,
        color=colour,
        alpha=BAND_ALPHA,
        lw=0,
        step="post" if stairs else None,
        label=f"{label}: min-max over drones",
        gid="envelope",
    )
    ax.plot(
        t_s,
        mid,
        color=colour,
        lw=1.4,
        label=f"{label}: median",
        drawstyle="steps-post" if stairs else "default",
    )


def draw_wind(ax: Axes, run: RunData, plane: tuple[int, int] = (0, 1)) -> None:
    """The plant's mean wind as an arrow in the upper right of ``ax`` (its projection on
    ``plane``, 28 points long whatever its speed), labelled with the speed and the gusts' std;
    nothing without wind."""
    if run.wind is None:
        return
    mean, std = run.wind
    label = f"wind {np.linalg.norm(mean):.2g} m/s" + (f", gusts {std:.2g} m/s std" if std > 0 else "")
    w = mean[list(plane)]
    anchor, fig = (0.9, 0.92), cast(Figure, ax.figure)  # a plan's axes sit on a Figure
    if np.linalg.norm(w) > 1e-6 * max(float(np.linalg.norm(mean)), 1e-12):
        u = 14.0 * w / np.linalg.norm(w)
        head = offset_copy(ax.transAxes, fig=fig, x=u[0], y=u[1], units="points")
        tail = offset_copy(ax.transAxes, fig=fig, x=-u[0], y=-u[1], units="points")
        style = {"arrowstyle": "-|>", "color": WIND_COLOUR, "lw": 1.8, "mutation_scale": 12}
        ax.annotate("", anchor, anchor, head, tail, arrowprops=style, zorder=6, gid=WIND_GID)
    else:
        label += " (across this view)"
    below = offset_copy(ax.transAxes, fig=fig, y=-18.0, units="points")
    ax.text(
        0.98, anchor[1], label, transform=below, ha="right", va="top", fontsize="x-small", color=WIND_COLOUR
    )


def note_plant_events(ax: Axes, run: RunData) -> None:
    """What the plant reported (crazyflow: drone contacts, drones on the floor or flipped, and
    when planning stopped for them), in red in the lower left of ``ax``; nothing if none."""
    events = plant_events(run.summary.get("plant") or {})
    if events is not None:
        ax.text(
            0.02, 0.02, events, transform=ax.transAxes, fontsize="x-small", color="tab:red", gid=EVENTS_GID
        )


def mark_closest_pair(ax: Axes, run: RunData, axes: tuple[int, int] = (0, 1)) -> None:
    """The two closest drones at the moment of minimum separation, joined by a red segment, with
    circles that touch when they are d_min apart (in a projection: scaled with the pair's
    projected distance, so projected circles overlap only for a pair really closer than d_min)."""
    if run.n < 2:
        return
    k, i, j, dist = closest_pair(run.trajectory.positions_m)
    xy = run.trajectory.positions_m[k][[i, j]][:, list(axes)]
    t = float(run.trajectory.t_s[k])
    ax.plot(
        xy[:, 0],
        xy[:, 1],
        color=CLOSEST_COLOUR,
        lw=2.2,
        marker="o",
        ms=5,
        zorder=6,
        label=f"closest pair {i}-{j}: {dist:.2f} m at t = {t:.3g} s",
    )
    if run.d_min_m is not None:  # circles that overlap exactly when the pair is closer than d_min:
        # radius d_min / 2, scaled in a projection of a spatial run as the pair's distance is
        seen = float(np.linalg.norm(xy[1] - xy[0]))
        radius = run.d_min_m / 2 * (seen / dist if dist > 0 else 1.0)
        for centre in xy:
            ax.add_patch(
                Circle(
                    tuple(centre),
                    radius,
                    fill=False,
                    color=CLOSEST_COLOUR,
                    lw=0.9,
                    ls="--",
                    zorder=6,
                )
            )


def draw_leaders(ax: Axes, xy: Array, run: RunData) -> None:
    """The leaders of a consensus run (stars) at positions ``xy`` (n, 2)."""
    leaders = list(run.formation.leaders)
    if leaders:
        ax.scatter(
            xy[leaders, 0],
            xy[leaders, 1],
            marker="*",
            s=170,
            color="gold",
            edgecolors="k",
            zorder=6,
            label="leader (sees the commanded scale)",
        )


def draw_graph(ax: Axes, run: RunData) -> None:
    """The communication graph on the template: numbered drones, one line per link, leaders starred."""
    graph, leaders = run.formation.graph_edges, list(run.formation.leaders)
    if graph is None:
        return
    r = run.formation.offsets_m[:, :2]
    for a, b in graph.astype(int):
        ax.plot(r[[a, b], 0], r[[a, b], 1], color="tab:green", lw=1.0)
    ax.scatter(r[:, 0], r[:, 1], s=90, color="white", edgecolors="tab:green", zorder=3)
    for i, (x, y) in enumerate(r):
        ax.text(x, y, str(i), ha="center", va="center", fontsize=6, zorder=4)
    if leaders:
        ax.scatter(r[leaders, 0], r[leaders, 1], marker="*", s=150, color="gold", edgecolors="k", zorder=5)
    ax.set_title(f"communication graph\n({graph.shape[0]} links, leader starred)", fontsize="x-small")
    ax.set(xticks=[], yticks=[], aspect="equal")
    ax.margins(0.15)


def plan_size(
    run: RunData, width_in: float = 6.5, legend_in: float = 0.0, min_height_in: float = 4.2
) -> tuple[float, float]:
    """Figure size for an equal-aspect x-y plot of the run: the height follows the data."""
    traj, d = run.trajectory, run.dim
    xy = np.concatenate([traj.positions_m[..., :2].reshape(-1, 2), traj.reference_m[..., :2].reshape(-1, 2)])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    for ob in run.obstacles:
        ring = ob.outline_m(d, (0, 1), ob.resolved_clearance_m)
        lo, hi = np.minimum(lo, ring.min(axis=0)), np.maximum(hi, ring.max(axis=0))
    span = np.maximum(hi - lo, 1.0)
    height = float(np.clip(width_in * span[1] / span[0] + 1.6, min_height_in, 9.0))
    return width_in + legend_in, height


def draw_obstacles(ax: Axes, run: RunData, axes: tuple[int, int] = (0, 1)) -> None:
    """Each obstacle as a grey patch in the plane of ``axes`` (its projection), its clearance as a
    dotted outline around it."""
    pts = np.concatenate([run.trajectory.positions_m, run.trajectory.reference_m])[..., list(axes)]
    lo, hi = pts.reshape(-1, 2).min(axis=0), pts.reshape(-1, 2).max(axis=0)
    pad = 0.5 * float(np.max(hi - lo)) + 1.0  # an unbounded obstacle stops beyond the data

    def clipped(ring: Array) -> Array:
        return np.clip(ring, lo - pad, hi + pad)

    for k, ob in enumerate(run.obstacles):  # clearances resolved (older runs' NaN: d_min / 2)
        body = clipped(ob.outline_m(run.dim, axes))
        ax.add_patch(Polygon(body, closed=True, color="0.75", zorder=1, label="obstacle" if k == 0 else None))
        if ob.resolved_clearance_m > 0:
            ring = clipped(ob.outline_m(run.dim, axes, ob.resolved_clearance_m))
            ax.add_patch(
                Polygon(
                    ring,
                    closed=True,
                    fill=False,
                    ls=":",
                    color="0.3",
                    zorder=1,
                    label="required clearance" if k == 0 else None,
                )
            )


def equal_3d(ax: Any, points: Array) -> None:
    """Equal, cubic 3D axes around ``points`` (m, 3), with at most 5 ticks per axis."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.5) * 1.05
    ax.set(
        xlim=(mid[0] - half, mid[0] + half),
        ylim=(mid[1] - half, mid[1] + half),
        zlim=(mid[2] - half, mid[2] + half),
    )
    ax.set_box_aspect((1, 1, 1))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
