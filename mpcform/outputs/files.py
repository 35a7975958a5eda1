"""The output files of a run, and a short readable summary for the terminal.

``mpcform run`` writes into its directory (these names and columns are a contract):

- ``trajectory.npz``: ``t`` (T,) [s], ``p`` (T, n, d) positions [m], ``u`` (T-1, n, d) the
  command [m/s] applied over ``[t_j, t_{j+1})``, ``p_ref`` (T, n, d) desired positions [m]; and
  the plant's dense true motion: ``t_true`` (K,) [s] (every control sample among them, at least
  10 per interval), ``p_true`` and ``v_true`` (K, n, d) [m, m/s], ``p_ref_true`` (K, n, d) [m],
  and for the quadrotor ``quat_true`` (K, n, 4, xyzw) and ``thrust_true`` (K, n) [N]; for a
  controller with per-drone scale estimates (consensus) ``scale_estimates`` (T, n), each drone's
  ``s_hat_i`` at every sample;
- ``trajectory.csv``: one row per time and drone, ``t, drone, x, y[, z], vx, vy[, vz],
  x_ref, y_ref[, z_ref]`` (the command columns are empty at the final time);
- ``summary.json``: ``scenario, n, dim, dt, steps, controller, solver``, ``limits``
  (``v_max``, ``d_min``; null where unset), ``provenance`` (mpcform, Python and dependency
  versions, seed, scenario file and hash) and ``metrics`` (:func:`mpcform.sim.metrics.run_metrics`);
  strict JSON, non-finite numbers written as null.
"""

from __future__ import annotations

import csv
import json
import math
import platform
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from mpcform.sim.trajectory import Trajectory

TRAJECTORY_NPZ = "trajectory.npz"
TRAJECTORY_CSV = "trajectory.csv"
SUMMARY_JSON = "summary.json"
OUTPUT_FILES = (TRAJECTORY_NPZ, TRAJECTORY_CSV, SUMMARY_JSON)
SUMMARY_KEYS = (
    "scenario",
    "n",
    "dim",
    "dt",
    "steps",
    "controller",
    "solver",
    "limits",
    "provenance",
    "metrics",
)
DEPENDENCIES = ("numpy", "scipy", "osqp", "piqp", "qpsolvers", "casadi", "ruckig")
AXES = ("x", "y", "z")


def csv_header(dim: int) -> list[str]:
    """``t, drone, x, y[, z], vx, vy[, vz], x_ref, y_ref[, z_ref]``."""
    axes = AXES[:dim]
    return ["t", "drone", *axes, *(f"v{a}" for a in axes), *(f"{a}_ref" for a in axes)]


TRUE_ARRAYS = {
    "t_true": "t_s",
    "p_true": "positions_m",
    "v_true": "velocities_mps",
    "p_ref_true": "reference_m",
    "quat_true": "quat_xyzw",
    "thrust_true": "thrust_N",
}
"""Keys of ``trajectory.npz`` for the :class:`~mpcform.sim.trajectory.TrueTrajectory` fields."""
SCALE_ESTIMATES = "scale_estimates"
FIGURE_FORMATS = ("png", "pdf", "svg")  # what the figures are written as (mpcform.outputs.figures)
FIGURE_DPI = 110  # their default resolution [dots per inch]
DPI_RANGE = (20, 1200)
"""Key of ``trajectory.npz`` for the per-drone scale estimates (T, n), written only when recorded."""


def write_trajectory_npz(path: Path, trajectory: Trajectory) -> None:
    """Arrays ``t`` (T,) [s], ``p`` (T, n, d) [m], ``u`` (T-1, n, d) [m/s], ``p_ref`` (T, n, d), the
    dense true motion when the trajectory has it (:data:`TRUE_ARRAYS`) and ``scale_estimates``
    (T, n) when it has them."""
    traj = trajectory
    true = {} if traj.true is None else {key: getattr(traj.true, name) for key, name in TRUE_ARRAYS.items()}
    optional = true | {SCALE_ESTIMATES: traj.scale_estimates}
    np.savez_compressed(
        path,
        t=traj.t_s,
        p=traj.positions_m,
        u=traj.commands_mps,
        p_ref=traj.reference_m,
        **{key: value for key, value in optional.items() if value is not None},
    )


def write_trajectory_csv(path: Path, trajectory: Trajectory) -> None:
    """One row per time and drone; the command columns are empty at the final time."""
    traj = trajectory
    steps, n, dim = traj.commands_mps.shape
    t = traj.t_s.tolist()
    p, u, ref = (a.tolist() for a in (traj.positions_m, traj.commands_mps, traj.reference_m))
    empty = [""] * dim
    with path.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(csv_header(dim))
        for j, tj in enumerate(t):
            for i in range(n):
                cmd = u[j][i] if j < steps else empty
                writer.writerow([repr(tj), i, *map(repr, p[j][i]), *map(_cell, cmd), *map(repr, ref[j][i])])


def provenance(
    seed: int, scenario_file: Path | None = None, scenario_sha256: str | None = None
) -> dict[str, Any]:
    """Versions of mpcform, Python and the numerical dependencies, the seed, the scenario hash."""
    return {
        "mpcform": _version("mpcform"),
        "python": platform.python_version(),
        "dependencies": {name: _version(name) for name in DEPENDENCIES},
        "seed": seed,
        "scenario_file": None if scenario_file is None else str(scenario_file),
        "scenario_sha256": scenario_sha256,
    }


def build_summary(
    *,
    scenario: str,
    n: int,
    dim: int,
    dt_s: float,
    steps: int,
    controller: str,
    solver: str | None,
    v_max_mps: float | None,
    d_min_m: float | None,
    seed: int,
    metrics: dict[str, Any],
    scenario_file: Path | None = None,
    scenario_sha256: str | None = None,
    plant: dict[str, Any] | None = None,
    tracking_m: float = 0.0,
    downwash_kappa: float | None = None,
    v_max_z_mps: float | None = None,
) -> dict[str, Any]:
    """The ``summary.json`` record (keys :data:`SUMMARY_KEYS`, and ``plant`` when given: the plant's
    kind, its robust margin and the acceleration limit the plan kept), JSON-safe (no NaN or inf).
    ``limits.tracking`` is the tracking allowance the plan kept (0: none; ``export`` refuses it),
    ``limits.downwash`` the downwash factor kappa (None: none), ``limits.v_max_z`` the vertical
    speed bound the plan kept (None: none)."""
    summary = {
        "scenario": scenario,
        "n": n,
        "dim": dim,
        "dt": dt_s,
        "steps": steps,
        "controller": controller,
        "solver": solver,
        "limits": {
            "v_max": v_max_mps,
            "d_min": d_min_m,
            "tracking": tracking_m,
            "downwash": downwash_kappa,
            "v_max_z": v_max_z_mps,
        },
        "provenance": provenance(seed, scenario_file, scenario_sha256),
        "metrics": metrics,
    }
    if plant is not None:
        summary["plant"] = plant
    return json_safe(summary)


def json_safe(value: Any) -> Any:
    """``value`` with numpy scalars as Python numbers and non-finite floats as None."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_summary_json(path: Path, summary: dict[str, Any]) -> None:
    """Strict JSON (``allow_nan=False``), indented, with a final newline."""
    path.write_text(json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")


def write_outputs(out_dir: Path, trajectory: Trajectory, summary: dict[str, Any]) -> Path:
    """Create ``out_dir`` (with parents) and write the three output files into it."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_trajectory_npz(out_dir / TRAJECTORY_NPZ, trajectory)
    write_trajectory_csv(out_dir / TRAJECTORY_CSV, trajectory)
    write_summary_json(out_dir / SUMMARY_JSON, summary)
    return out_dir


def incomplete_warning(summary: dict[str, Any]) -> str | None:
    """One line when the run ended with drones away from their final targets (None otherwise)."""
    m = summary["metrics"]
    if not m.get("incomplete_drones"):
        return None
    n, k = summary["n"], len(m["incomplete_drones"])
    return (
        f"the run ended incomplete: {k} of {n} drones not at their final targets: {_away(m)}, "
        f"{m['stalled_drones']} of them stalled"
    )


def plant_events(plant: dict[str, Any]) -> str | None:
    """One line of what a plant saw happen (crazyflow: contacts, floor contacts, flips, and when
    planning stopped for a lost drone); None when nothing did."""
    said = [
        f"{what}: {', '.join(str(x) for x in plant[key])}"
        for key, what in (
            ("drone_contacts", "drone contacts"),
            ("floor_contacts", "on the floor"),
            ("flipped", "flipped"),
        )
        if plant.get(key)
    ]
    if stopped := plant.get("planning_stopped_s"):
        said.append(
            "planning stopped for " + ", ".join(f"drone {i} at {t:.3g} s" for i, t in stopped.items())
        )
    return "; ".join(said) or None


def _away(m: dict[str, Any]) -> str:
    """``drones 2, 5 (0.65 m, 8.9 m away)``, the first eight listed."""
    ids, dist = m["incomplete_drones"], m["incomplete_distances_m"]
    more = f", +{len(ids) - 8} more" if len(ids) > 8 else ""
    listed = ", ".join(str(i) for i in ids[:8]) + more
    away = ", ".join(f"{d:.3g} m" for d in dist[:8]) + (", ..." if more else "")
    return f"drone{'s' * (len(ids) > 1)} {listed} ({away} away)"


def format_summary(summary: dict[str, Any]) -> str:
    """A short aligned table of the run and its metrics, for the terminal."""
    m, lim = summary["metrics"], summary["limits"]
    plant: dict[str, Any] = summary.get("plant") or {}
    flying = plant.get("kind", "ideal") != "ideal"  # a plant other than the plan
    solver = f", solver {summary['solver']}" if summary["solver"] else ""
    rows = [
        (
            "scenario",
            f"{summary['scenario']} (n = {summary['n']}, {summary['dim']}D, "
            f"{summary['steps']} steps of {summary['dt']:g} s)",
        ),
        ("controller", f"{summary['controller']}{solver}"),
        ("final tracking error", _m(m["final_tracking_error"], "m")),
        ("max tracking error", _m(m["max_tracking_error"], "m")),
        (
            "min separation",
            f"{_m(m['min_separation'], 'm')} at samples, "
            f"{_m(m['min_separation_segments'], 'm')} along segments "
            f"(d_min {_m(lim['d_min'], 'm')})",
        ),
        ("max speed", f"{_m(m['max_speed'], 'm/s')} (v_max {_m(lim['v_max'], 'm/s')})"),
        ("violations", _violations(m, "")),
        (
            "qp solves",
            f"{m['qp_solves']} ({m['fast_path_steps']} fast-path steps, "
            f"{m['solver_failures']} failures, max slack {_m(m['max_slack'], 'm')})",
        ),
    ]
    if m.get("max_wind_shift"):  # in wind: the rows' growth's premise (mpc.premise)
        over = f"above the growth on {m['growth_exceeded_steps']} steps"
        rows.append(("wind shift", f"at most {_m(m['max_wind_shift'], 'm')} per step, {over}"))
    if m.get("growth_slack_steps"):
        used = f"{m['growth_slack_steps']} steps, at most {_m(m['max_growth_slack'], 'm')}"
        rows.append(("growth buffer used", f"{used} (required distances kept)"))
    if "completion" in m:
        done = m["time_to_complete"]
        end = f" from t = {done:.4g} s" if done is not None else f", {m['stalled_drones']} stalled"
        rows.append(("completion", f"{m['completion']:.0%} of drones at their final targets{end}"))
        if m.get("incomplete_drones"):
            rows.append(("not arrived", _away(m)))
    if "obstacle_violations" in m:
        flown = ""  # and a plant's dense motion's (the ideal plant's is the same path)
        if flying and "min_obstacle_clearance_true" in m:
            flown = f" (true motion {_m(m['min_obstacle_clearance_true'], 'm')})"
        rows.append(
            (
                "obstacles",
                f"min clearance {_m(m['min_obstacle_clearance'], 'm')} from a surface{flown}, "
                f"{m['obstacle_violations']} violations",
            )
        )
    if flying and "min_separation_true" in m:
        model = ", its velocity loop in the rows" if plant.get("velocity_loop_modelled") else ""
        rows.append(
            (
                "true motion",
                f"{plant['kind']} plant (margin {_m(plant['margin'], 'm')}{model}): min "
                f"separation {_m(m['min_separation_true'], 'm')}, violations {_violations(m, '_true')}, "
                f"max speed {_m(m['max_speed_true'], 'm/s')}",
            )
        )
    if (events := plant_events(plant)) is not None:
        rows.append(("plant events", events))
    for mode, st in m["step_time_ms"].items():
        rows.append(
            (
                f"step time {mode}",
                f"median {st['median']:.3g} ms, p90 {st['p90']:.3g} ms, max {st['max']:.3g} ms",
            )
        )
    width = max(len(label) for label, _ in rows)
    return "\n".join(f"{label:<{width}}  {value}" for label, value in rows)


def _violations(m: dict[str, Any], suffix: str) -> str:
    """The violations of the path (``suffix`` ``_true``: of the dense true motion) by kind."""
    kinds = [
        ("separation", "separation"),
        ("speed", "speed"),
        ("obstacle", "obstacle"),
        ("geofence", "geofence"),
    ]
    said = [
        f"{m[f'{key}_violations{suffix}']} {name}" for key, name in kinds if f"{key}_violations{suffix}" in m
    ]
    return ", ".join(said)


def _m(value: float | None, unit: str) -> str:
    return "-" if value is None else f"{value:.4g} {unit}"


def _cell(x: float | str) -> str:
    return x if isinstance(x, str) else repr(x)


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None
