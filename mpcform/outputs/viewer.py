"""An interactive viewer of a run: one self-contained HTML file (no network, no library).

:func:`write_viewer_html` writes a page that plays the drones' flight in 2-D (top view) or 3-D
(orbit, zoom, pan) with a time slider, play/pause at real time (0.25x to 8x), the formation's
edges, the obstacles, the geofence and the pairs closer than d_min (red), beside the metric
curves (see :func:`viewer_curves`; a plant run's :func:`flown_curves`, and its flown path
dotted) with a cursor linked to the time. The page is drawn with
the browser's Canvas 2D API by ``static/viewer.js``; the data is embedded as compact JSON
(positions in integer millimetres, curves to 4 significant digits), so a 20-drone run of a
few hundred samples is ~0.1 MB. Open ``<file>#t=5.2`` to start at t = 5.2 s.

Curve keys carry their unit (``_m``, ``_mps``, ``_s``, ...); a curve whose key holds
``separation`` gets the d_min line, one whose key holds ``speed`` the v_max line, and a curve
without such a line spanning more than two decades of positive values gets a log axis.
"""

from __future__ import annotations

import html
import json
import math
import re
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array, finite_array, positive
from mpcform.errors import ValidationError
from mpcform.formation.geometry import closest_pair, min_pair_distances, pairs_within
from mpcform.outputs.viewer_obstacles import obstacle_payload
from mpcform.sim.metrics import REL_TOL
from mpcform.sim.trajectory import TrueTrajectory
from mpcform.world.obstacles import Obstacle

SEPARATION_KEY = "min_separation_m"
SPEED_KEY = "max_speed_mps"
TRACKING_KEY = "max_tracking_error_m"
TRACKING_FLOOR_M = 1e-6  # tracking errors shown no smaller (rounding would stretch a log axis to 1e-13)
FLOWN_SEPARATION_KEY = "flown_min_separation_m"  # a plant run's dense true path (flown_curves)
FLOWN_SPEED_KEY = "flown_max_speed_mps"
FLOWN_PER_STEP = 5  # flown path samples drawn per control interval (50 Hz at dt 0.1 s)
UNITS = {"_mps2": "m/s²", "_mps": "m/s", "_m": "m", "_s": "s", "_rad": "rad", "_deg": "°"}
LOG_DECADES = 2.0  # positive curves spanning more decades than this get a log axis
_PLACEHOLDER = re.compile(r"/\*@(CSS|JS|DATA)@\*/|@TITLE@")


def write_viewer_html(
    path: str | Path,
    *,
    t_s: Array,
    positions_m: Array,
    d_min_m: float | None = None,
    v_max_mps: float | None = None,
    edges: Array | Sequence[tuple[int, int]] = (),
    obstacles: tuple[Obstacle, ...] | None = (),
    geofence: tuple[Array, Array] | None = None,
    reference_m: Array | None = None,
    title: str = "mpcform run",
    curves: Mapping[str, Array] | None = None,
    flown: TrueTrajectory | None = None,
    wind: tuple[Array, float] | None = None,
    events: str | None = None,
) -> Path:
    """Write the viewer of a run to ``path`` (parents created); returns the path.

    ``t_s`` (T,) increasing; ``positions_m`` and ``reference_m`` (T, n, d), d = 2 or 3;
    ``edges`` (E, 2) drone index pairs; ``obstacles``: shapes of :mod:`mpcform.world.shapes` (an unset
    clearance: d_min / 2, :mod:`mpcform.outputs.viewer_obstacles`); ``geofence``: (min, max)
    corners (d,) of a box, +-inf for open sides; ``curves``: name -> (T,) values (NaN: none);
    ``flown``: a plant run's dense true path, drawn dotted (at most :data:`FLOWN_PER_STEP`
    samples per control interval: :func:`flown_samples`); ``wind``: the plant's mean wind [m/s]
    (d,) and gust std [m/s], drawn as an arrow in the legend; ``events``: what the plant reported
    (:func:`mpcform.outputs.files.plant_events`), in red under the title.
    """
    data = viewer_payload(
        t_s=t_s,
        positions_m=positions_m,
        d_min_m=d_min_m,
        v_max_mps=v_max_mps,
        edges=edges,
        obstacles=obstacles,
        geofence=geofence,
        reference_m=reference_m,
        title=title,
        curves=curves,
        flown=flown,
        wind=wind,
        events=events,
    )
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render_html(data), encoding="utf-8")
    return out


def viewer_curves(
    t_s: Array, positions_m: Array, *, reference_m: Array | None = None, commands_mps: Array | None = None
) -> dict[str, Array]:
    """The standard curves (T,): min separation, max speed, max tracking error over drones (no
    smaller than :data:`TRACKING_FLOOR_M`).

    The speed is that of the commands (T - 1, n, d) held over each step (NaN at the last
    sample), else of the positions' finite differences; separation needs two drones.
    """
    t = _times(t_s)
    p = _positions("positions_m", positions_m, t.shape[0])
    curves: dict[str, Array] = {}
    if p.shape[1] >= 2:
        curves[SEPARATION_KEY] = min_pair_distances(p)
    if commands_mps is not None:
        u = finite_array("commands_mps", commands_mps, (t.shape[0] - 1, p.shape[1], p.shape[2]))
        speed = np.linalg.norm(u, axis=-1).max(axis=1) if u.shape[0] else np.empty(0)
    else:
        dt = np.diff(t)[:, None]
        speed = (np.linalg.norm(np.diff(p, axis=0), axis=-1) / dt).max(axis=1)
    curves[SPEED_KEY] = np.append(speed, np.nan)
    if reference_m is not None:
        ref = _positions("reference_m", reference_m, t.shape[0], p.shape[1:])
        curves[TRACKING_KEY] = np.maximum(np.linalg.norm(p - ref, axis=-1).max(axis=1), TRACKING_FLOOR_M)
    return curves


def flown_curves(t_s: Array, true: TrueTrajectory) -> dict[str, Array]:
    """A plant run's dense true path as curves (T,) on the control samples: over each interval
    ``[t_k, t_k+1)`` the smallest distance between two drones and the largest true speed (the
    last sample: its own), so the true extremes show at the viewer's rate."""
    t = _times(t_s)
    starts = np.searchsorted(true.t_s, t, side="left").clip(max=true.t_s.shape[0] - 1)
    speed = np.linalg.norm(true.velocities_mps, axis=-1).max(axis=1)
    curves = {FLOWN_SPEED_KEY: np.maximum.reduceat(speed, starts)}
    if true.positions_m.shape[1] >= 2:
        curves[FLOWN_SEPARATION_KEY] = np.minimum.reduceat(min_pair_distances(true.positions_m), starts)
    return curves


def flown_samples(t_true_s: Array, samples: int) -> Array:
    """Indices of a dense true path's times ``t_true_s`` (K,) for display: every ``stride``-th,
    so at most :data:`FLOWN_PER_STEP` per interval of a run of ``samples`` control samples, and the
    last (the peaks and minima come from the full path: :func:`flown_curves`)."""
    k = t_true_s.shape[0]
    stride = max(1, math.ceil((k - 1) / (FLOWN_PER_STEP * max(1, samples - 1))))
    return np.unique(np.append(np.arange(0, k, stride), k - 1))


def viewer_payload(
    *,
    t_s: Array,
    positions_m: Array,
    d_min_m: float | None = None,
    v_max_mps: float | None = None,
    edges: Array | Sequence[tuple[int, int]] = (),
    obstacles: tuple[Obstacle, ...] | None = (),
    geofence: tuple[Array, Array] | None = None,
    reference_m: Array | None = None,
    title: str = "mpcform run",
    curves: Mapping[str, Array] | None = None,
    flown: TrueTrajectory | None = None,
    wind: tuple[Array, float] | None = None,
    events: str | None = None,
) -> dict[str, Any]:
    """The checked, rounded JSON object that the page reads (see :func:`write_viewer_html`)."""
    t = _times(t_s)
    p = _positions("positions_m", positions_m, t.shape[0])
    n, d = p.shape[1:]
    d_min = None if d_min_m is None else positive("d_min_m", d_min_m)
    v_max = None if v_max_mps is None else positive("v_max_mps", v_max_mps)
    payload: dict[str, Any] = {
        "title": str(title),
        "n": n,
        "dim": d,
        "t_s": [_sig(x, 9) for x in t],
        "p_mm": _millimetres(p),
        "ref_mm": None,
        "edges": _edges(edges, n),
        "obstacles": obstacle_payload(obstacles, d, d_min, p),
        "fence": _geofence(geofence, d),
        "d_min_m": d_min,
        "v_max_mps": v_max,
        "below": {},
        "closest": _closest(p),
        "curves": [_curve(k, v, t.shape[0], d_min, v_max) for k, v in (curves or {}).items()],
        "flown": None,
        "wind": None,
        "events": None if events is None else str(events),
    }
    if wind is not None:
        mean = finite_array("wind", wind[0], (d,))
        payload["wind"] = {
            "mean_mps": [_sig(x) for x in mean],
            "gust_std_mps": _sig(positive("gust_std", wind[1], allow_zero=True)),
        }
    if flown is not None:
        keep = flown_samples(flown.t_s, t.shape[0])
        payload["flown"] = {
            "t_s": [_sig(x, 9) for x in flown.t_s[keep]],
            "p_mm": _millimetres(_positions("flown", flown.positions_m[keep], keep.shape[0], (n, d))),
        }
    if reference_m is not None:
        payload["ref_mm"] = _millimetres(_positions("reference_m", reference_m, t.shape[0], (n, d)))
    if d_min is not None:
        limit = d_min * (1.0 - REL_TOL)  # counted as the run's metrics count violations
        for k, pk in enumerate(p):
            pairs = pairs_within(pk, limit)
            if pairs.shape[0]:
                payload["below"][str(k)] = pairs.ravel().tolist()
    return payload


def render_html(data: dict[str, Any]) -> str:
    """The page with ``data`` (a :func:`viewer_payload`), its script and style inlined."""
    static = resources.files("mpcform.outputs").joinpath("static")
    parts = {
        "CSS": static.joinpath("viewer.css").read_text(encoding="utf-8"),
        "JS": static.joinpath("viewer.js").read_text(encoding="utf-8"),
        "DATA": _script_json(data),
        "TITLE": html.escape(str(data["title"])),
    }
    page = static.joinpath("viewer.html").read_text(encoding="utf-8")
    return _PLACEHOLDER.sub(lambda m: parts[m.group(1) or "TITLE"], page)


# ---- checks and encodings ---------------------------------------------------------------
def _times(t_s: Array) -> Array:
    t = finite_array("t_s", t_s, (None,))
    if t.shape[0] < 1 or np.any(np.diff(t) <= 0):
        raise ValidationError("t_s", f"expected at least one strictly increasing time, got {t.tolist()[:8]}")
    return t


def _positions(field: str, value: Array, samples: int, shape: tuple[int, int] | None = None) -> Array:
    p = finite_array(field, value, (samples, None, None) if shape is None else (samples, *shape))
    if p.shape[1] < 1 or p.shape[2] not in (2, 3):
        raise ValidationError(field, f"expected (T, n >= 1, 2 or 3) positions, got shape {p.shape}")
    return p


def _millimetres(p: Array) -> list[int]:
    return [int(v) for v in np.rint(p * 1e3).astype(np.int64).ravel()]


def _sig(x: float, digits: int = 4) -> float | None:
    return float(f"{x:.{digits}g}") if math.isfinite(x) else None


def _edges(edges: Array | Sequence[tuple[int, int]], n: int) -> list[list[int]]:
    arr = np.asarray(edges, dtype=float).reshape(-1, 2) if len(edges) else np.empty((0, 2))
    if np.any(arr != np.round(arr)) or np.any((arr < 0) | (arr >= n)):
        raise ValidationError("edges", f"expected (E, 2) drone indices in [0, {n}), got {arr.tolist()}")
    return arr.astype(int).tolist()


def _geofence(geofence: tuple[Array, Array] | None, d: int) -> dict[str, list[float | None]] | None:
    if geofence is None:
        return None
    try:
        lo, hi = (np.array(corner, dtype=float).reshape(-1) for corner in geofence)
    except (TypeError, ValueError) as exc:
        raise ValidationError(
            "geofence", f"expected (min, max) corners of {d} numbers, got {geofence!r}"
        ) from exc
    if lo.shape != (d,) or hi.shape != (d,) or np.any(np.isnan(lo) | np.isnan(hi)) or np.any(lo >= hi):
        raise ValidationError(
            "geofence",
            f"expected (min, max) with min < max per axis, {d} numbers each, "
            f"got {lo.tolist()} and {hi.tolist()}",
        )
    return {"min_m": [_sig(v, 6) for v in lo], "max_m": [_sig(v, 6) for v in hi]}


def _closest(p: Array) -> dict[str, Any] | None:
    """The run's closest pair: its sample ``k``, the ``pair`` and their distance ``m`` [m]."""
    if p.shape[1] < 2:
        return None
    k, i, j, dist = closest_pair(p)
    return {"k": k, "pair": [i, j], "m": _sig(dist)}


def _curve(key: str, values: Array, samples: int, d_min: float | None, v_max: float | None) -> dict[str, Any]:
    field = f"curves[{key!r}]"
    try:
        y = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValidationError(field, f"expected ({samples},) numbers, got {values!r}") from exc
    if y.shape != (samples,) or np.any(np.isinf(y)):
        raise ValidationError(field, f"expected ({samples},) finite numbers or NaN, got shape {y.shape}")
    name, unit = str(key), ""
    for suffix, label in UNITS.items():
        if name.endswith(suffix):
            name, unit = name[: -len(suffix)], label
            break
    limit = None
    if "separation" in key and d_min is not None:
        limit = {"value": d_min, "label": f"d_min = {d_min:g} m", "kind": "min"}
    elif "speed" in key and v_max is not None:
        limit = {"value": v_max, "label": f"v_max = {v_max:g} m/s", "kind": "max"}
    pos = y[np.isfinite(y) & (y > 0)]
    spread = float(np.log10(pos.max() / pos.min())) if pos.size else 0.0
    log = limit is None and bool(np.all(y[np.isfinite(y)] >= 0)) and spread > LOG_DECADES
    return {
        "key": key,
        "label": name.replace("_", " "),
        "unit": unit,
        "y": [_sig(v) for v in y],
        "limit": limit,
        "log": log,
    }


def _script_json(data: dict[str, Any]) -> str:
    """JSON that cannot close its ``<script>`` element (``<``, ``>``, ``&`` escaped)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
