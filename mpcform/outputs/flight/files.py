"""The per-drone CSV files of a flight export, written and read back.

``droneNNN[_ascent|_descent]_poly7[_partK].csv`` (the mission's without a phase name):
Crazyswarm ``uav_trajectories`` format, header
``Duration,x^0,...,x^7,y^0,...,z^0,...,yaw^0,...,yaw^7``, one row per piece, coefficients in
ascending powers of the time since the piece's start [s]. ``droneNNN[_phase]_setpoints.csv``:
``t, x, y, z, vx, vy, vz, ax, ay, az, yaw, omega_x, omega_y, omega_z`` [s, m, m/s, m/s^2, rad, rad/s].
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.outputs.flight.limits import flat_state
from mpcform.outputs.flight.pieces import CRAZYFLIE_MAX_PIECES, PhasePieces
from mpcform.outputs.flight.polynomial import POLY_DEGREE, PiecewisePolynomial

SETPOINT_COLUMNS = (
    "t",
    "x",
    "y",
    "z",
    "vx",
    "vy",
    "vz",
    "ax",
    "ay",
    "az",
    "yaw",
    "omega_x",
    "omega_y",
    "omega_z",
)
POLY_AXES = ("x", "y", "z", "yaw")
POLY_HEADER = ("Duration", *(f"{a}^{m}" for a in POLY_AXES for m in range(POLY_DEGREE + 1)))


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


def write_setpoints(path: Path, state: dict[str, Array], i: int) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(SETPOINT_COLUMNS)
        cols = np.column_stack(
            [
                state["t"],
                state["pos"][:, i],
                state["vel"][:, i],
                state["acc"][:, i],
                state["yaw"][:, i],
                state["omega"][:, i],
            ]
        )
        writer.writerows([[repr(x) for x in row] for row in cols.tolist()])
    return path


def write_poly(path: Path, durations: Array, coef: Array) -> Path:
    """``coef`` (K, 4, 8) for x, y, z, yaw."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(POLY_HEADER)
        for duration, c in zip(durations.tolist(), coef.tolist(), strict=True):
            writer.writerow([repr(x) for x in (duration, *c[0], *c[1], *c[2], *c[3])])
    return path


def write_phase(out: Path, stems: list[str], part: PhasePieces, rate_hz: float) -> list[Path]:
    """One phase's files per drone ``stems[i]``: ``<stem>[_<phase>]_setpoints.csv`` at ``rate_hz``
    and ``<stem>[_<phase>]_poly7.csv`` (the mission's without a phase name; split into ``_partK``
    files above the Crazyflie's pieces)."""
    flown, n = part.flown, len(stems)
    tag = "" if part.name == "mission" else f"_{part.name}"
    t = np.append(np.arange(0.0, flown.duration_s, 1.0 / rate_hz), flown.duration_s)
    sp = flat_state(flown, t, n) | {"t": t}
    coef = flown.coefficients.reshape(flown.pieces, n, 4, -1)
    chunks = [
        range(s, min(s + CRAZYFLIE_MAX_PIECES, flown.pieces))
        for s in range(0, flown.pieces, CRAZYFLIE_MAX_PIECES)
    ]
    files: list[Path] = []
    for i, stem in enumerate(stems):
        files.append(write_setpoints(out / f"{stem}{tag}_setpoints.csv", sp, i))
        for k, chunk in enumerate(chunks, start=1):
            suffix = "" if len(chunks) == 1 else f"_part{k}"
            rows = list(chunk)
            files.append(
                write_poly(out / f"{stem}{tag}_poly7{suffix}.csv", flown.durations_s[rows], coef[rows, i])
            )
    return files
