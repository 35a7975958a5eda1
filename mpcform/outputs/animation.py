"""``flight.gif``: an animation of a run (matplotlib on an Agg canvas, frames written by pillow).

Imported only when an animation is asked for, like :mod:`mpcform.outputs.figures`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mpcform._validate import Array
from mpcform.outputs.drawing import (
    draw_obstacles,
    drone_colours,
    equal_3d,
    formation_edges,
    marker_scale,
    plan_size,
)
from mpcform.outputs.rundata import RunData

ANIMATION_FILE = "flight.gif"


def animate_run(run: RunData, path: str | Path, *, max_frames: int = 80, fps: int = 12,
                trail_s: float = 3.0) -> Path:  # fmt: skip
    """Write a GIF of the flight (top view; 3D for spatial runs) with trails and the reference.

    At most ``max_frames`` frames evenly spaced in time, shown at ``fps`` frames per second.
    """
    from PIL import Image  # pillow: a dependency of matplotlib, listed in the plot extra

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    p, ref, t = run.trajectory.positions_m, run.trajectory.reference_m, run.trajectory.t_s
    frames = np.unique(np.linspace(0, t.shape[0] - 1, min(max_frames, t.shape[0])).round().astype(int))
    trail = max(1, int(round(trail_s / float(t[1] - t[0]))))
    colours = drone_colours(run.n)
    edges = formation_edges(run.formation.offsets_m)
    spatial = run.dim == 3
    d = 3 if spatial else 2
    legend_in = 2.0  # the legend sits right of the axes, off the flight
    width, height = (6.0 + legend_in, 5.6) if spatial else plan_size(run, 6.0, legend_in, 3.0)
    fig = Figure(figsize=(width, height), dpi=96)  # fixed margins: no layout engine per frame
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.8 / width, right=1.0 - (legend_in + 0.1) / width, bottom=0.65 / height,
                        top=1.0 - 0.65 / height)  # fmt: skip
    ax: Any = fig.add_subplot(projection="3d") if spatial else fig.add_subplot()
    lo = np.minimum(p.min(axis=(0, 1)), ref.min(axis=(0, 1)))[:d]
    hi = np.maximum(p.max(axis=(0, 1)), ref.max(axis=(0, 1)))[:d]
    if spatial:
        equal_3d(ax, np.stack([lo, hi]))
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
    else:
        draw_obstacles(ax, run)
        pad = 0.08 * float((hi - lo).max()) + 0.5
        ax.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad), xlabel="x [m]",
               ylabel="y [m]")  # fmt: skip
        ax.set_aspect("equal", adjustable="box")
        ax.grid(True, alpha=0.3)
    trails = [ax.plot(*p[:1, i, :d].T, color=colours[i], lw=1.0, alpha=0.7)[0] for i in range(run.n)]
    links = [ax.plot(*np.zeros((d, 2)), color="0.4", lw=0.8)[0] for _ in edges]
    ms = 6.0 * float(np.sqrt(marker_scale(run.n)))  # marker diameter [pt]
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


def _set_data(line: Any, xyz: Array, spatial: bool) -> None:
    line.set_data(xyz[:, 0], xyz[:, 1])
    if spatial:
        line.set_3d_properties(xyz[:, 2])
