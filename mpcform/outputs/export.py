"""Trajectories a flight stack can consume: setpoint streams and Crazyswarm polynomial files.

For every drone of a run (:class:`~mpcform.outputs.rundata.RunData`, in memory after
``mpcform run --export`` or read back by :func:`~mpcform.outputs.rundata.load_run`):

- ``droneNNN_setpoints.csv``: ``t, x, y, z, vx, vy, vz, ax, ay, az, yaw`` at every sample,
  for streaming full-state setpoints. Positions are the planned (simulated) positions;
  velocities and accelerations are their central differences (one-sided at the ends), so
  the three are consistent: without lag or noise the velocity at ``t_j`` is the mean of the
  commands before and after it. Yaw is 0 (the formation's rotation is not a drone's yaw).
- ``droneNNN_poly7.csv``: the same path as 7th-order polynomial pieces in the format of the
  Crazyswarm ``uav_trajectories`` tools (header ``Duration,x^0,...,x^7,y^0,...,yaw^7``,
  coefficients in ascending powers of the time since the start of the piece [s]), fitted by
  :func:`mpcform.outputs.polynomial.fit_positions`: uniform pieces, continuous up to the jerk,
  as few as reproduce every planned position within ``tolerance_m`` (with float32
  coefficients, as the Crazyflie stores them).
  The Crazyflie keeps trajectories in 4096 bytes of memory, 31 such pieces: longer fits are
  split into ``droneNNN_poly7_partK.csv`` files of at most 31 pieces, with a warning.

Planar runs fly at a constant ``altitude_m``. ``provenance.json`` beside the files records
the versions, seed and scenario hash of the run and of the export, and the fit's accuracy.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError
from mpcform.outputs.files import json_safe, provenance
from mpcform.outputs.polynomial import (
    DEFAULT_TOLERANCE_M,
    MAX_PIECE_S,
    POLY_DEGREE,
    PiecewisePolynomial,
    PolynomialFit,
    fit_positions,
    max_speed,
)
from mpcform.outputs.rundata import RunData
from mpcform.sim.trajectory import Trajectory

CRAZYFLIE_MAX_PIECES = 31  # crazyflie-firmware: TRAJECTORY_MEMORY_SIZE 4096 B / 132 B per poly4d piece
DEFAULT_ALTITUDE_M = 1.0
SETPOINT_COLUMNS = ("t", "x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "yaw")
POLY_AXES = ("x", "y", "z", "yaw")
POLY_HEADER = ("Duration", *(f"{a}^{m}" for a in POLY_AXES for m in range(POLY_DEGREE + 1)))
PROVENANCE_JSON = "provenance.json"
SPEED_SLACK = 1.1  # warn when the pieces are faster than this times v_max


@dataclass(frozen=True)
class ExportResult:
    """Files written, the fit, and warnings for the user (too many pieces, below the floor)."""

    directory: Path
    files: tuple[Path, ...]
    fit: PolynomialFit
    files_per_drone: int
    warnings: tuple[str, ...]


def setpoints(trajectory: Trajectory, altitude_m: float | None = None) -> tuple[Array, Array, Array]:
    """Positions, velocities and accelerations (T, n, 3) of the planned path (z = altitude if planar)."""
    p = _positions_3d(trajectory, altitude_m)
    d, t = trajectory.dim, trajectory.t_s
    vel = np.zeros_like(p)  # planar: vz = az = 0 exactly
    vel[..., :d] = np.gradient(trajectory.positions_m, t, axis=0, edge_order=1)
    acc = np.zeros_like(p)
    acc[..., :d] = np.gradient(vel[..., :d], t, axis=0, edge_order=1)
    return p, vel, acc


def export_run(
    run: RunData,
    out_dir: str | Path,
    *,
    altitude_m: float | None = None,
    tolerance_m: float = DEFAULT_TOLERANCE_M,
    max_piece_s: float = MAX_PIECE_S,
) -> ExportResult:
    """Write the setpoint and polynomial CSV files of every drone and ``provenance.json``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    pos, vel, acc = setpoints(run.trajectory, altitude_m)
    for stale in [*out.glob("drone*_setpoints.csv"), *out.glob("drone*_poly7*.csv")]:
        stale.unlink()  # an earlier export (perhaps split into more parts) of this directory
    t = run.trajectory.t_s
    fit = fit_positions(t, run.trajectory.positions_m, tolerance_m, max_piece_s)  # planar: z is exact
    warnings: list[str] = []
    if not fit.within_tolerance:
        warnings.append(f"the polynomial pieces miss the planned positions by up to {fit.max_error_m:.3g} m "
                        f"(tolerance {tolerance_m:g} m) at two samples per piece")  # fmt: skip
    metrics = run.summary.get("metrics") or {}
    if metrics.get("separation_violations"):
        warnings.append(f"the planned flight itself brings drones closer than d_min = {run.d_min_m:g} m "
                        f"({metrics['separation_violations']} sample pairs, down to "
                        f"{metrics.get('min_separation_segments') or 0.0:.3g} m): do not fly it")  # fmt: skip
    poly_speed = max_speed(fit.polynomial, run.n)
    if run.v_max_mps is not None and poly_speed > SPEED_SLACK * run.v_max_mps:
        warnings.append(f"the polynomial pieces reach {poly_speed:.3g} m/s, above v_max = "
                        f"{run.v_max_mps:g} m/s (the commands keep it): lower --tolerance")  # fmt: skip
    chunks = [range(s, min(s + CRAZYFLIE_MAX_PIECES, fit.polynomial.pieces))
              for s in range(0, fit.polynomial.pieces, CRAZYFLIE_MAX_PIECES)]  # fmt: skip
    if len(chunks) > 1:
        warnings.append(f"{fit.polynomial.pieces} pieces per drone exceed the Crazyflie's "
                        f"{CRAZYFLIE_MAX_PIECES}: split into {len(chunks)} files per drone (upload and fly "
                        "them in turn), or raise --tolerance")  # fmt: skip
    if float(pos[..., 2].min()) < 0.0:
        warnings.append(f"z goes down to {float(pos[..., 2].min()):.3g} m, below the floor z = 0: shift "
                        "the scenario up (or pass --altitude for a planar run) before flying")  # fmt: skip
    width = max(3, len(str(run.n - 1)))
    files: list[Path] = []
    coef = np.zeros((fit.polynomial.pieces, run.n, 3, POLY_DEGREE + 1))
    coef[:, :, : run.dim] = fit.polynomial.coefficients.reshape(fit.polynomial.pieces, run.n, run.dim, -1)
    if run.dim == 2:
        coef[:, :, 2, 0] = pos[0, 0, 2]  # constant altitude
    for i in range(run.n):
        stem = f"drone{i:0{width}d}"
        path = out / f"{stem}_setpoints.csv"
        _write_setpoints(path, t - t[0], pos[:, i], vel[:, i], acc[:, i])
        files.append(path)
        for part, chunk in enumerate(chunks, start=1):
            suffix = "" if len(chunks) == 1 else f"_part{part}"
            path = out / f"{stem}_poly7{suffix}.csv"
            _write_poly(path, fit.polynomial.durations_s[list(chunk)], coef[list(chunk), i])
            files.append(path)
    record = {
        "export": provenance(
            int(run.summary.get("provenance", {}).get("seed") or 0),
            _str_or_none(run.summary.get("provenance", {}).get("scenario_file")),
            run.summary.get("provenance", {}).get("scenario_sha256"),
        ),  # fmt: skip
        "run": run.summary.get("provenance"),
        "source": str(run.directory),
        "scenario": run.name,
        "files": {
            "setpoints": "droneNNN_setpoints.csv: " + ",".join(SETPOINT_COLUMNS) + " [s, m, m/s, m/s^2, rad]",
            "polynomials": "droneNNN_poly7[_partK].csv: Crazyswarm uav_trajectories format, "
            "ascending powers of the time since the piece's start [s]",
        },  # fmt: skip
        "altitude_m": None if run.dim == 3 else _altitude(altitude_m),
        "pieces": fit.polynomial.pieces,
        "piece_duration_s": float(fit.polynomial.durations_s[0]),
        "files_per_drone": len(chunks),
        "crazyflie_max_pieces": CRAZYFLIE_MAX_PIECES,
        "tolerance_m": tolerance_m,
        "max_fit_error_m": fit.max_error_m,
        "max_polynomial_speed_mps": poly_speed,
        "warnings": warnings,
    }
    prov = out / PROVENANCE_JSON
    prov.write_text(json.dumps(json_safe(record), indent=2, allow_nan=False) + "\n")
    files.append(prov)
    return ExportResult(out, tuple(files), fit, len(chunks), tuple(warnings))


def read_setpoints(path: str | Path) -> dict[str, Array]:
    """Columns of a setpoint CSV as float arrays."""
    with Path(path).open(newline="") as f:
        rows = list(csv.DictReader(f))
    return {c: np.array([float(r[c]) for r in rows]) for c in SETPOINT_COLUMNS}


def read_poly(paths: list[Path] | list[str]) -> PiecewisePolynomial:
    """The pieces of one drone from its polynomial CSV file(s), in order; series x, y, z, yaw."""
    rows: list[list[float]] = []
    for path in paths:
        with Path(path).open(newline="") as f:
            reader = csv.reader(f)
            header = next(reader)
            if tuple(header) != POLY_HEADER:
                raise ValidationError(str(path), f"unexpected header {header[:3]}...")
            rows += [[float(x) for x in row] for row in reader]
    data = np.array(rows)
    return PiecewisePolynomial(0.0, data[:, 0], data[:, 1:].reshape(-1, 4, POLY_DEGREE + 1))


def _write_setpoints(path: Path, t: Array, p: Array, v: Array, a: Array) -> None:
    with path.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(SETPOINT_COLUMNS)
        for row in zip(t.tolist(), p.tolist(), v.tolist(), a.tolist(), strict=True):
            writer.writerow([repr(row[0]), *map(repr, row[1]), *map(repr, row[2]), *map(repr, row[3]), "0.0"])


def _write_poly(path: Path, durations: Array, coef: Array) -> None:
    """``coef`` (K, 3, 8) for x, y, z; the yaw polynomial is zero."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(POLY_HEADER)
        zeros = [0.0] * (POLY_DEGREE + 1)
        for duration, c in zip(durations.tolist(), coef.tolist(), strict=True):
            writer.writerow([repr(x) for x in (duration, *c[0], *c[1], *c[2], *zeros)])


def _altitude(altitude_m: float | None) -> float:
    return DEFAULT_ALTITUDE_M if altitude_m is None else positive("altitude", altitude_m)


def _positions_3d(trajectory: Trajectory, altitude_m: float | None) -> Array:
    p = trajectory.positions_m
    if trajectory.dim == 3:
        if altitude_m is not None:
            raise ValidationError("altitude", "applies only to planar runs; a spatial run exports its own z")
        return p.copy()
    z = np.full((*p.shape[:2], 1), _altitude(altitude_m))
    return np.concatenate([p, z], axis=-1)


def _str_or_none(value: Any) -> Path | None:
    return None if value is None else Path(str(value))
