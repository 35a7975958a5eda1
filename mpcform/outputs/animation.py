"""The flight as a video: ``flight.mp4`` (matplotlib's ffmpeg writer, when ffmpeg is installed)
or ``flight.gif`` (pillow), drawn with :class:`matplotlib.animation.FuncAnimation` on an Agg canvas.

The video plays the flight at ``speed`` times real time (default 1: a 20 s flight lasts 20 s),
with at most ``max_frames`` frames: a long flight gets fewer frames per second, never a shorter
video. Every frame writes the flight time and the speed factor. A planar run is seen from above;
a spatial run in two projections (x-y and x-z), which keep depth readable without a camera. Pairs
closer than d_min are joined in red, drones carry their index (up to 20 drones), and a run on a
plant other than the ideal one shows its dense true path (what the drones really did).
``progress(done, total)`` is called after each frame (the CLI draws a bar with it).

Imported only when an animation is asked for, like :mod:`mpcform.outputs.figures`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.animation import AbstractMovieWriter, FFMpegWriter, FuncAnimation
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.geometry import pairs_within
from mpcform.outputs.drawing import (
    CLOSEST_COLOUR,
    PATH_GREY,
    PER_DRONE_MAX,
    draw_obstacles,
    draw_wind,
    drone_colours,
    marker_scale,
    skeleton_edges,
)
from mpcform.outputs.rundata import RunData
from mpcform.sim.metrics import REL_TOL

ANIMATION_FILE = "flight.gif"
MP4_FILE = "flight.mp4"
FPS_CHOICES = (20, 10, 5, 4, 2, 1)  # frame rates whose frame time is a whole number of 10 ms (GIF)
MAX_FRAMES = 300
TRAIL_S = 3.0
IDS_MAX = 20  # drones up to this many carry their index
AXIS_NAMES = ("x", "y", "z")

Progress = Callable[[int, int], None]


def animation_file(kind: str = "auto") -> str:
    """``flight.gif`` or ``flight.mp4`` for ``kind`` ``gif`` or ``mp4``; ``auto``: ``flight.mp4``
    when matplotlib finds ffmpeg, else ``flight.gif``."""
    if kind == "auto":
        return MP4_FILE if FFMpegWriter.isAvailable() else ANIMATION_FILE
    return {"gif": ANIMATION_FILE, "mp4": MP4_FILE}[kind]


def frame_times(
    t0_s: float, t1_s: float, speed: float = 1.0, fps: int = 10, max_frames: int = MAX_FRAMES
) -> tuple[Array, int]:
    """Flight times of the frames and the frame rate: frames ``speed / fps`` seconds of flight
    apart, at the highest rate of :data:`FPS_CHOICES` up to ``fps`` that needs at most
    ``max_frames`` frames. The video lasts ``(t1 - t0) / speed`` seconds (plus one frame)."""
    if not speed > 0 or not math.isfinite(speed):
        raise ValidationError("speed", f"expected a positive real-time factor, got {speed!r}")
    if max_frames < 2:
        raise ValidationError("max_frames", f"expected at least 2, got {max_frames!r}")
    video_s = (t1_s - t0_s) / speed
    rates = [f for f in FPS_CHOICES if f <= max(fps, 1)] or [1]
    rate = next((f for f in rates if video_s * f + 1 <= max_frames), rates[-1])
    count = min(max_frames, int(math.floor(video_s * rate + 1e-9)) + 1)
    return t0_s + np.arange(count) * speed / rate, rate


def animate_run(
    run: RunData,
    path: str | Path,
    *,
    speed: float = 1.0,
    fps: int = 10,
    max_frames: int = MAX_FRAMES,
    progress: Progress | None = None,
    dpi: int = 80,
) -> Path:
    """Write the flight to ``path``: MP4 for a ``.mp4`` suffix (needs ffmpeg), else a GIF."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mp4 = path.suffix.lower() == ".mp4"
    if mp4 and not FFMpegWriter.isAvailable():
        raise ValidationError(str(path), "an MP4 needs ffmpeg on the PATH; write a .gif instead")
    t = run.trajectory.t_s
    times, rate = frame_times(float(t[0]), float(t[-1]), speed, fps, max_frames)
    scene = FlightScene(run, speed, dpi)
    anim = FuncAnimation(
        scene.fig,
        scene.update,
        frames=times,
        init_func=lambda: [],
        blit=False,
        interval=1000 / rate,
        repeat=False,
        cache_frame_data=False,
    )
    writer = FFMpegWriter(fps=rate) if mp4 else GifWriter(scene.render, fps=rate)
    callback = None if progress is None else (lambda i, n: progress(i + 1, n))
    anim.save(str(path), writer=writer, dpi=dpi, progress_callback=callback)
    return path


class GifWriter(AbstractMovieWriter):
    """A GIF writer (pillow) that takes each frame from ``render()`` (an (h, w, 3) uint8 image):
    the scene redraws only its moving artists over a cached background (blitting), several times
    faster than a full redraw per frame. Every frame lasts exactly ``1000 / fps`` ms."""

    def __init__(self, render: Callable[[], Array], fps: int) -> None:
        super().__init__(fps=fps)
        self.render = render
        self.images: list[Any] = []

    def setup(self, fig: Any, outfile: Any, dpi: float | None = None) -> None:
        super().setup(fig, outfile, dpi=dpi)
        self.images = []

    def grab_frame(self, **savefig_kwargs: Any) -> None:
        from PIL import Image  # pillow: a dependency of matplotlib, listed in the plot extra

        self.images.append(Image.fromarray(self.render()))

    def finish(self) -> None:
        self.images[0].save(
            self.outfile,
            save_all=True,
            append_images=self.images[1:],
            duration=int(round(1000 / self.fps)),
            loop=0,
        )


class _FrameCanvas(FigureCanvasAgg):
    """An Agg canvas that ignores the full redraw FuncAnimation asks for after each frame
    (``draw_idle``): the writer draws the frame itself (blitting for GIFs, a full draw for MP4)."""

    def draw_idle(self, *args: Any, **kwargs: Any) -> None:
        pass


class FlightScene:
    """The figure of the animation and its moving artists; :meth:`update` draws flight time t."""

    def __init__(self, run: RunData, speed: float, dpi: int) -> None:
        self.run, self.speed = run, speed
        self.background: Any = None
        self.planes = ((0, 1),) if run.dim == 2 else ((0, 1), (0, 2))
        self.edges = skeleton_edges(run)
        path = run.flown or run.trajectory  # a plant run shows what the drones really did
        self.path_t, self.path_p = path.t_s, path.positions_m
        p, ref = self.path_p, run.trajectory.reference_m
        both = np.concatenate([p.reshape(-1, run.dim), ref.reshape(-1, run.dim)])
        span = np.maximum(both.max(axis=0) - both.min(axis=0), 1.0)
        ratio = max(span[b] / span[a] for a, b in self.planes)
        panel_in = (6.4 if ratio >= 0.6 else 9.0) if run.dim == 2 else 5.0  # a wide flight: a wide frame
        height = float(np.clip(panel_in * ratio + 1.6, 3.6, 7.5))
        self.fig = Figure(figsize=frame_size_in(panel_in * len(self.planes), height, dpi), dpi=dpi)
        self.fig.set_layout_engine("constrained")
        _FrameCanvas(self.fig)
        axes = self.fig.subplots(1, len(self.planes), squeeze=False)[0]
        few = run.n <= PER_DRONE_MAX
        colours = drone_colours(run.n) if few else ["tab:blue"] * run.n
        ms = max(4.5, 6.0 * float(np.sqrt(marker_scale(run.n))))  # points: 5 px or more at 80 dpi
        self.artists: list[dict[str, Any]] = []
        close_label = None if run.d_min_m is None else "closer than d_min"
        ids = run.n if run.n <= IDS_MAX else 0
        for ax, (a, b) in zip(axes, self.planes, strict=True):
            draw_obstacles(ax, run, (a, b))
            draw_wind(ax, run, (a, b))
            both = np.concatenate([p[..., [a, b]].reshape(-1, 2), ref[..., [a, b]].reshape(-1, 2)])
            lo, hi = both.min(axis=0), both.max(axis=0)
            pad = 0.06 * float((hi - lo).max()) + 0.3
            ax.set(
                xlim=(lo[0] - pad, hi[0] + pad),
                ylim=(lo[1] - pad, hi[1] + pad),
                xlabel=f"{AXIS_NAMES[a]} [m]",
                ylabel=f"{AXIS_NAMES[b]} [m]",
                aspect="equal",
            )
            ax.grid(True, alpha=0.3)
            trail_colour = colours if few else [PATH_GREY] * run.n
            self.artists.append(
                {
                    "plane": (a, b),
                    "trails": [ax.plot([], [], color=c, lw=1.0, alpha=0.7)[0] for c in trail_colour],
                    "links": [ax.plot([], [], color="0.3", lw=1.0)[0] for _ in self.edges],
                    "refs": ax.plot(
                        [],
                        [],
                        ls="none",
                        marker="o",
                        ms=1.5 * ms,
                        mfc="none",
                        mec="k",
                        mew=0.6,
                        label="reference p*_i",
                    )[0],
                    "leaders": ax.plot(
                        [],
                        [],
                        ls="none",
                        marker="*",
                        ms=13,
                        mfc="gold",
                        mec="k",
                        mew=0.6,
                        zorder=5,
                        label="leader" if run.formation.leaders else None,
                    )[0],
                    "close": ax.plot([], [], color=CLOSEST_COLOUR, lw=2.2, zorder=4.5, label=close_label)[0],
                    "ids": [
                        ax.text(*p[0, i, [a, b]], str(i), fontsize=7, zorder=6, clip_on=True, in_layout=False)
                        for i in range(ids)
                    ],
                    "drones": ax.scatter(
                        p[0, :, a],
                        p[0, :, b],
                        s=ms**2,
                        c=colours,
                        zorder=4,
                        edgecolors="k",
                        linewidths=0.3,
                        label="drones",
                    ),
                }
            )
            ax.set_title(
                f"{AXIS_NAMES[a]}-{AXIS_NAMES[b]}" + (" (top view)" if (a, b) == (0, 1) else ""),
                fontsize="small",
            )
        self.artists[0]["trails"][0].set_label(f"last {TRAIL_S:g} s")
        handles, labels = axes[0].get_legend_handles_labels()
        self.fig.legend(
            handles, labels, loc="outside lower center", ncol=5, fontsize="x-small", frameon=False
        )
        self.clock = self.fig.suptitle(f"{run.label}   t = 000.00 s", fontsize="medium", family="monospace")
        for _ in range(3):  # lay the figure out, then keep it: no layout pass per frame
            self.fig.canvas.draw()  # a first pass can leave the panels' titles under the clock
            if not self.titles_overlap():
                break
        self.fig.set_layout_engine("none")

    def titles_overlap(self) -> bool:
        """Whether the clock (the figure's title) overlaps a panel's title (as last drawn)."""
        renderer: Any = self.fig.canvas.get_renderer()  # type: ignore[attr-defined]
        clock = self.clock.get_window_extent(renderer)
        return any(ax.title.get_window_extent(renderer).overlaps(clock) for ax in self.fig.axes)

    def update(self, t_s: float) -> list[Any]:
        """Move every artist to flight time ``t_s`` (positions interpolated between samples)."""
        traj, path_t, path_p = self.run.trajectory, self.path_t, self.path_p
        p, ref = _at(path_t, path_p, t_s), _at(traj.t_s, traj.reference_m, t_s)
        window = (path_t >= t_s - TRAIL_S) & (path_t <= t_s)
        d_min = self.run.d_min_m
        close = np.empty((0, 2), dtype=int) if d_min is None else pairs_within(p, d_min * (1.0 - REL_TOL))
        for art in self.artists:
            a, b = art["plane"]
            for i, line in enumerate(art["trails"]):
                line.set_data(
                    np.append(path_p[window, i, a], p[i, a]), np.append(path_p[window, i, b], p[i, b])
                )
            gaps = np.full((close.shape[0], 1), np.nan)  # one line, a NaN between the pairs
            art["close"].set_data(
                np.hstack([p[close, a], gaps]).ravel(), np.hstack([p[close, b], gaps]).ravel()
            )
            for i, label in enumerate(art["ids"]):
                label.set_position((p[i, a], p[i, b]))
            for (i, j), line in zip(self.edges, art["links"], strict=True):
                line.set_data(p[[i, j], a], p[[i, j], b])
            art["refs"].set_data(ref[:, a], ref[:, b])
            art["drones"].set_offsets(p[:, [a, b]])
            leaders = list(self.run.formation.leaders)
            art["leaders"].set_data(p[leaders, a], p[leaders, b])
        factor = "real time" if self.speed == 1 else f"{self.speed:g}x real time"
        self.clock.set_text(f"{self.run.label}   t = {t_s:6.2f} s   ({factor})")
        return []

    def moving(self) -> list[Any]:
        """The artists that change from frame to frame."""
        arts = [self.clock]
        for art in self.artists:
            arts += [*art["trails"], *art["links"], art["refs"], art["drones"], art["leaders"], art["close"]]
            arts += art["ids"]
        return arts

    def render(self) -> Array:
        """The current frame as an (h, w, 3) uint8 image: the still background (drawn once)
        with the moving artists drawn over it."""
        canvas: Any = self.fig.canvas
        moving = self.moving()
        if self.background is None:
            for artist in moving:
                artist.set_visible(False)
            canvas.draw()
            self.background = canvas.copy_from_bbox(self.fig.bbox)
            for artist in moving:
                artist.set_visible(True)
        canvas.restore_region(self.background)
        for artist in moving:
            self.fig.draw_artist(artist)
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def frame_size_in(width_in: float, height_in: float, dpi: int) -> tuple[float, float]:
    """A figure size near ``width_in`` x ``height_in`` that is an even number of pixels each way at
    ``dpi``: the GIF's frames and the MP4's (H.264 wants even sizes) are then the same."""
    return 2 * round(width_in * dpi / 2) / dpi, 2 * round(height_in * dpi / 2) / dpi


def _at(t_s: Array, values: Array, t: float) -> Array:
    """``values`` (T, n, d) linearly interpolated at time ``t``."""
    k = int(np.clip(np.searchsorted(t_s, t, side="right") - 1, 0, t_s.shape[0] - 2))
    w = float(np.clip((t - t_s[k]) / (t_s[k + 1] - t_s[k]), 0.0, 1.0))
    return np.asarray((1 - w) * values[k] + w * values[k + 1])
