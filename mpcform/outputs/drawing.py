"""Drawing pieces shared by the figures and the animation: drone colours, marker sizes, the
formation's skeleton, obstacles, plan-view sizes and equal 3D axes (matplotlib).

Imported only when plots are asked for, like :mod:`mpcform.outputs.figures` and
:mod:`mpcform.outputs.animation`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.patches import Circle
from matplotlib.ticker import MaxNLocator
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial.distance import pdist, squareform

from mpcform._validate import Array
from mpcform.outputs.rundata import RunData

DRONE_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
                 "tab:olive", "tab:cyan")  # fmt: skip
PER_DRONE_MAX = len(DRONE_COLOURS)  # up to this many drones: one legend entry / speed line per drone


def formation_edges(offsets_m: Array) -> list[tuple[int, int]]:
    """Edges of the minimum spanning tree of the template offsets (draws any shape's skeleton)."""
    n = offsets_m.shape[0]
    if n < 2:
        return []
    dist = squareform(pdist(offsets_m)) + 1e-12 * (1 - np.eye(n))  # keep coincident points linked
    tree = minimum_spanning_tree(dist).tocoo()
    return sorted((int(min(a, b)), int(max(a, b))) for a, b in zip(tree.row, tree.col, strict=True))


def drone_colours(n: int) -> list[Any]:
    """Distinct colours without grey (the formation snapshots are grey) up to 9, else viridis."""
    if n <= len(DRONE_COLOURS):
        return list(DRONE_COLOURS[:n])
    return [colormaps["viridis"](i / max(1, n - 1)) for i in range(n)]


def marker_scale(n: int) -> float:
    """Smaller markers for large swarms (1 up to 20 drones, 0.3 at 100)."""
    return float(min(1.0, max(0.3, 20.0 / max(n, 1))))


def plan_size(
    run: RunData, width_in: float = 6.5, legend_in: float = 2.8, min_height_in: float = 4.2
) -> tuple[float, float]:
    """Figure size for an equal-aspect x-y plot of the run: the height follows the data."""
    traj, obstacles, d = run.trajectory, run.formation.obstacles, run.dim
    xy = np.concatenate([traj.positions_m[..., :2].reshape(-1, 2), traj.reference_m[..., :2].reshape(-1, 2)])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    for row in obstacles:
        reach = float(row[d]) + (float(row[d + 1]) if np.isfinite(row[d + 1]) else 0.0)
        lo, hi = np.minimum(lo, row[:2] - reach), np.maximum(hi, row[:2] + reach)
    span = np.maximum(hi - lo, 1.0)
    height = float(np.clip(width_in * span[1] / span[0] + 1.3, min_height_in, 9.0))
    return width_in + legend_in, height


def draw_obstacles(ax: Axes, run: RunData) -> None:
    """Each obstacle as a grey disc in the x-y plane, its clearance as a dotted ring."""
    d_min = run.d_min_m
    for k, row in enumerate(run.formation.obstacles):
        centre, radius, clearance = row[:2], float(row[run.dim]), float(row[run.dim + 1])
        if not np.isfinite(clearance):
            clearance = 0.5 * d_min if d_min is not None else 0.0
        ax.add_patch(Circle(tuple(centre), radius, color="0.75", zorder=1,
                            label="obstacle" if k == 0 else None))  # fmt: skip
        if clearance > 0:
            ax.add_patch(Circle(tuple(centre), radius + clearance, fill=False, ls=":", color="0.4",
                                zorder=1, label="obstacle + clearance" if k == 0 else None))  # fmt: skip


def equal_3d(ax: Any, points: Array) -> None:
    """Equal, cubic 3D axes around ``points`` (m, 3), with at most 5 ticks per axis."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.5) * 1.05
    ax.set(xlim=(mid[0] - half, mid[0] + half), ylim=(mid[1] - half, mid[1] + half),
           zlim=(mid[2] - half, mid[2] + half))  # fmt: skip
    ax.set_box_aspect((1, 1, 1))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
