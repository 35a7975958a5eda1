"""The output files of a run, and a short readable summary for the terminal.

``mpcform run`` writes into its directory (these names and columns are a contract):

- ``trajectory.npz``: ``t`` (T,) [s], ``p`` (T, n, d) positions [m], ``u`` (T-1, n, d) the
  command [m/s] applied over ``[t_j, t_{j+1})``, ``p_ref`` (T, n, d) desired positions [m];
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
SUMMARY_KEYS = ("scenario", "n", "dim", "dt", "steps", "controller", "solver", "limits",
                "provenance", "metrics")  # fmt: skip
DEPENDENCIES = ("numpy", "scipy", "osqp", "piqp", "qpsolvers", "casadi", "ruckig")
AXES = ("x", "y", "z")


def csv_header(dim: int) -> list[str]:
    """``t, drone, x, y[, z], vx, vy[, vz], x_ref, y_ref[, z_ref]``."""
    axes = AXES[:dim]
    return ["t", "drone", *axes, *(f"v{a}" for a in axes), *(f"{a}_ref" for a in axes)]


def write_trajectory_npz(path: Path, trajectory: Trajectory) -> None:
    """Arrays ``t`` (T,) [s], ``p`` (T, n, d) [m], ``u`` (T-1, n, d) [m/s], ``p_ref`` (T, n, d)."""
    traj = trajectory
    np.savez_compressed(path, t=traj.t_s, p=traj.positions_m, u=traj.commands_mps, p_ref=traj.reference_m)


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
                writer.writerow([repr(tj), i, *map(repr, p[j][i]), *map(_cell, cmd),
                                 *map(repr, ref[j][i])])  # fmt: skip


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
) -> dict[str, Any]:
    """The ``summary.json`` record (keys :data:`SUMMARY_KEYS`), JSON-safe (no NaN or inf)."""
    summary = {
        "scenario": scenario,
        "n": n,
        "dim": dim,
        "dt": dt_s,
        "steps": steps,
        "controller": controller,
        "solver": solver,
        "limits": {"v_max": v_max_mps, "d_min": d_min_m},
        "provenance": provenance(seed, scenario_file, scenario_sha256),
        "metrics": metrics,
    }
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


def format_summary(summary: dict[str, Any]) -> str:
    """A short aligned table of the run and its metrics, for the terminal."""
    m, lim = summary["metrics"], summary["limits"]
    solver = f", solver {summary['solver']}" if summary["solver"] else ""
    rows = [
        ("scenario", f"{summary['scenario']} (n = {summary['n']}, {summary['dim']}D, "
                     f"{summary['steps']} steps of {summary['dt']:g} s)"),
        ("controller", f"{summary['controller']}{solver}"),
        ("final tracking error", _m(m["final_tracking_error"], "m")),
        ("max tracking error", _m(m["max_tracking_error"], "m")),
        ("min separation", f"{_m(m['min_separation'], 'm')} at samples, "
                           f"{_m(m['min_separation_segments'], 'm')} along segments "
                           f"(d_min {_m(lim['d_min'], 'm')})"),
        ("max speed", f"{_m(m['max_speed'], 'm/s')} (v_max {_m(lim['v_max'], 'm/s')})"),
        ("violations", f"{m['separation_violations']} separation, {m['speed_violations']} speed"),
        ("qp solves", f"{m['qp_solves']} ({m['fast_path_steps']} fast-path steps, "
                      f"{m['solver_failures']} failures, max slack {_m(m['max_slack'], 'm')})"),
    ]  # fmt: skip
    for mode, st in m["step_time_ms"].items():
        rows.append((f"step time {mode}", f"median {st['median']:.3g} ms, p90 {st['p90']:.3g} ms, "
                                          f"max {st['max']:.3g} ms"))  # fmt: skip
    width = max(len(label) for label, _ in rows)
    return "\n".join(f"{label:<{width}}  {value}" for label, value in rows)


def _m(value: float | None, unit: str) -> str:
    return "-" if value is None else f"{value:.4g} {unit}"


def _cell(x: float | str) -> str:
    return x if isinstance(x, str) else repr(x)


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None
