"""A finished run as the figures and the exports see it: its trajectory, formation data and summary.

A run directory holds ``trajectory.npz`` and ``summary.json`` (:mod:`mpcform.outputs.files`).
The figures and the exports also need what only the scenario knows: the template offsets (for
the best-fit scale and the formation's edges), the reference's scale and the obstacles.
``mpcform run --plot/--export`` takes them from the scenario in memory (:func:`formation_data`)
and saves them as ``formation.npz`` beside the other files: ``offsets`` (n, d) [m],
``scale_ref`` (T,), ``obstacle_records``: the obstacles as a JSON list of their scenario keys
(:meth:`mpcform.world.shapes.base.Shape.to_keys`, every kind; runs saved before shapes had kinds
hold spheres as ``obstacles`` (k, d + 2) [m], centre, radius and clearance, a NaN clearance being
d_min / 2, and still load),
``geofence`` (2, d) [m] when the run has one, and for a consensus run ``graph_edges`` (m, 2) and
``leaders`` (k,) (the communication graph's links
and the drones that see the commanded scale; absent otherwise).
:func:`load_run` reads a directory back into the same :class:`RunData`; without
``formation.npz`` it falls back to the reference's start shape (scale then relative to the start).
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.outputs.files import SCALE_ESTIMATES, SUMMARY_JSON, TRAJECTORY_NPZ, TRUE_ARRAYS
from mpcform.outputs.saved_checks import (
    RunDirError,
    check_formation_arrays,
    check_trajectory_arrays,
    load_npz,
    read_summary,
)
from mpcform.sim.trajectory import Trajectory, TrueTrajectory
from mpcform.world.obstacles import Obstacle, resolve_clearances
from mpcform.world.shapes import Sphere, shape_from_keys

if TYPE_CHECKING:
    from mpcform.scenario.spec import Scenario

FORMATION_NPZ = "formation.npz"


@dataclass(frozen=True, eq=False)
class FormationData:
    """The scenario's side of a run: ``offsets_m`` (n, d), the template (or, without
    ``formation.npz``, the reference's start shape ``s0 R0 r_i``); ``scale_ref`` (T,), the
    reference's scale, or None when unknown; ``obstacles``: the obstacles as saved (an unset
    clearance: d_min / 2, :attr:`RunData.obstacles`);
    ``graph_edges`` (m, 2), the communication graph of a consensus run (None: no graph),
    ``leaders``, its drones that see the commanded scale, and ``geofence_m`` (2, d), the box's
    min and max corners (None: no fence)."""

    offsets_m: Array
    scale_ref: Array | None
    obstacles: tuple[Obstacle, ...]
    graph_edges: Array | None = None
    leaders: tuple[int, ...] = ()
    geofence_m: Array | None = None

    @property
    def scale_is_relative(self) -> bool:
        """True when the scale is measured relative to the start (no reference scale known)."""
        return self.scale_ref is None


@dataclass(frozen=True, eq=False)
class RunData:
    """One run: its trajectory, formation data, ``summary.json`` record and output directory."""

    trajectory: Trajectory
    formation: FormationData
    summary: dict[str, Any]
    directory: Path

    @property
    def n(self) -> int:
        return self.trajectory.n

    @property
    def dim(self) -> int:
        return self.trajectory.dim

    @property
    def name(self) -> str:
        return str(self.summary.get("scenario") or self.directory.name)

    @property
    def d_min_m(self) -> float | None:
        return _limit(self.summary, "d_min")

    @property
    def tracking_m(self) -> float:
        """The tracking allowance the plan kept (0: none, or a run saved before it was recorded)."""
        return _limit(self.summary, "tracking") or 0.0

    @property
    def downwash_kappa(self) -> float | None:
        """The downwash factor the plan kept (``limits.downwash``; None: none)."""
        return _limit(self.summary, "downwash")

    @property
    def downwash_metric(self) -> Array | None:
        """``diag(1, 1, 1 / kappa)`` of the downwash ellipsoid (None: none)."""
        kappa = self.downwash_kappa
        return None if kappa is None else np.array([1.0, 1.0, 1.0 / kappa])

    @property
    def v_max_mps(self) -> float | None:
        return _limit(self.summary, "v_max")

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The saved obstacles with their clearances resolved: an unset clearance (a run saved
        before the clearance was resolved on loading) is half of the run's d_min."""
        return resolve_clearances(self.formation.obstacles, self.d_min_m)

    @property
    def flown(self) -> TrueTrajectory | None:
        """The dense true motion of a run on a plant other than the ideal one (None otherwise: the
        ideal plant flies the plan's own straight segments)."""
        plant = (self.summary.get("plant") or {}).get("kind", "ideal")
        return None if plant == "ideal" else self.trajectory.true

    @property
    def wind(self) -> tuple[Array, float] | None:
        """The plant's mean wind [m/s] (d,) and its gusts' std [m/s] (None without wind, or a run
        saved before the wind was recorded)."""
        wind = (self.summary.get("plant") or {}).get("wind")
        if not wind:
            return None
        return np.asarray(wind["mean_mps"], dtype=float), float(wind.get("gust_std_mps") or 0.0)

    @property
    def label(self) -> str:
        """``<scenario> (<controller>[, <solver>])``, for titles and legends."""
        solver = self.summary.get("solver")
        ctrl = str(self.summary.get("controller", "?")) + (f", {solver}" if solver else "")
        return f"{self.name} ({ctrl})"


def formation_data(scenario: Scenario, t_s: Array) -> FormationData:
    """The formation data of ``scenario`` with the reference's scale sampled at ``t_s``."""
    consensus = scenario.controller.consensus if scenario.controller.kind == "consensus" else None
    return FormationData(
        offsets_m=np.array(scenario.template.offsets),
        scale_ref=np.asarray(scenario.reference.profile(np.asarray(t_s, dtype=float)).scale, dtype=float),
        obstacles=tuple(scenario.obstacles),
        graph_edges=None if scenario.graph is None else np.array(scenario.graph.edges, dtype=int),
        leaders=() if consensus is None else tuple(int(i) for i in consensus.leaders),
        geofence_m=_fence(scenario),
    )


def _fence(scenario: Scenario) -> Array | None:
    lim = scenario.limits
    if lim.geofence_min_m is None or lim.geofence_max_m is None:
        return None
    return np.stack([lim.geofence_min_m, lim.geofence_max_m])


def write_formation_npz(out_dir: str | Path, formation: FormationData) -> Path:
    """Write ``formation.npz`` (offsets (n, d) [m], scale_ref (T,), obstacle_records (JSON); with a
    communication graph also graph_edges (m, 2) and leaders (k,))."""
    if formation.scale_ref is None:
        raise ValidationError("formation.scale_ref", "unknown (a run read back without formation.npz)")
    path = Path(out_dir) / FORMATION_NPZ
    arrays: dict[str, Any] = {
        "offsets": formation.offsets_m,
        "scale_ref": formation.scale_ref,
        "obstacle_records": np.array(json.dumps([ob.to_keys() for ob in formation.obstacles])),
    }
    if formation.graph_edges is not None:
        arrays |= {"graph_edges": formation.graph_edges, "leaders": np.array(formation.leaders, dtype=int)}
    if formation.geofence_m is not None:
        arrays["geofence"] = formation.geofence_m
    np.savez_compressed(path, **arrays)
    return path


def load_run(directory: str | Path) -> RunData:
    """Read ``trajectory.npz`` (with its optional arrays), ``summary.json`` and, when present,
    ``formation.npz``."""
    root = Path(directory)
    if not root.is_dir():
        raise RunDirError(str(root), "no such run directory (write one with `mpcform run --out DIR`)")
    arrays = _npz(root / TRAJECTORY_NPZ, ("t", "p", "u", "p_ref"), optional=(*TRUE_ARRAYS, SCALE_ESTIMATES))
    check_trajectory_arrays(root / TRAJECTORY_NPZ, arrays)  # shapes, finite values: saved_checks
    try:
        true = None
        if "t_true" in arrays:
            true = TrueTrajectory(**{name: arrays.get(key) for key, name in TRUE_ARRAYS.items()})  # type: ignore[arg-type]
        trajectory = Trajectory(
            arrays["t"],
            arrays["p"],
            arrays["u"],
            arrays["p_ref"],
            true=true,
            scale_estimates=arrays.get(SCALE_ESTIMATES),
        )
    except ValidationError as exc:
        raise RunDirError(str(root / TRAJECTORY_NPZ), str(exc)) from None
    summary = read_summary(root / SUMMARY_JSON)
    return RunData(trajectory, _load_formation(root / FORMATION_NPZ, trajectory), summary, root)


def _load_formation(path: Path, trajectory: Trajectory) -> FormationData:
    n, d = trajectory.n, trajectory.dim
    if not os.path.lexists(path):  # a dangling or looping link is no missing file: refused below
        ref0 = trajectory.reference_m[0]
        return FormationData(ref0 - ref0.mean(axis=0), None, ())
    extra = _npz(path, ("offsets", "scale_ref"), optional=("obstacles", "graph_edges", "leaders", "geofence"))
    check_formation_arrays(path, extra, n, d, trajectory.t_s.shape[0])
    graph = extra.get("graph_edges")
    return FormationData(
        extra["offsets"],
        extra["scale_ref"],
        _load_obstacles(path, extra.get("obstacles"), d),
        graph_edges=None if graph is None else graph.astype(int).reshape(-1, 2),
        leaders=tuple(int(i) for i in extra.get("leaders", np.empty(0))),
        geofence_m=None if "geofence" not in extra else extra["geofence"].reshape(2, d),
    )


def _load_obstacles(path: Path, legacy: Array | None, d: int) -> tuple[Obstacle, ...]:
    """The obstacles of ``formation.npz``: its ``obstacle_records``, or an older run's sphere rows."""
    try:
        with load_npz(path) as npz:
            text = str(npz["obstacle_records"]) if "obstacle_records" in npz.files else None
        if text is None:
            rows = np.empty((0, d + 2)) if legacy is None else legacy.reshape(-1, d + 2)
            return tuple(
                Sphere(r[:d], float(r[d]), float(r[d + 1]) if np.isfinite(r[d + 1]) else None) for r in rows
            )
        records = json.loads(text)
        if not isinstance(records, list) or not all(isinstance(r, dict) for r in records):
            raise ValueError("expected a JSON list of tables")
        return tuple(shape_from_keys(r) for r in records)
    except (ValueError, TypeError, KeyError) as exc:
        raise RunDirError(str(path), f"cannot read its obstacles: {exc}") from None


def _npz(path: Path, keys: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict[str, Array]:
    try:
        with load_npz(path) as npz:  # size and arrays' headers checked first
            missing = [k for k in keys if k not in npz.files]
            if missing:
                raise RunDirError(str(path), f"missing arrays {missing} (has {sorted(npz.files)})")
            return {k: np.asarray(npz[k], dtype=float) for k in (*keys, *optional) if k in npz.files}
    except RunDirError:
        raise
    except FileNotFoundError:
        raise RunDirError(str(path), "missing (write it with `mpcform run --out DIR`)") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:  # truncated, corrupt
        raise RunDirError(str(path), f"cannot read it as a numpy .npz archive: {exc}") from None


def _limit(summary: dict[str, Any], key: str) -> float | None:
    value = (summary.get("limits") or {}).get(key)
    return None if value is None else float(value)
