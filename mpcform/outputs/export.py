"""Trajectories a flight stack can consume: setpoint streams and Crazyswarm polynomial files.

For every drone of a saved run (:func:`mpcform.outputs.rundata.load_run`):

- ``droneNNN_setpoints.csv``: ``t, x, y, z, vx, vy, vz, ax, ay, az, yaw`` at every sample,
  for streaming full-state setpoints. Positions are the planned (simulated) positions;
  velocities and accelerations are their central differences (one-sided at the ends), so
  the three are consistent: without lag or noise the velocity at ``t_j`` is the mean of the
  commands before and after it. Yaw is 0 (the formation's rotation is not a drone's yaw).
- ``droneNNN_poly7.csv``: the same path as 7th-order polynomial pieces in the format of the
  Crazyswarm ``uav_trajectories`` tools (header ``Duration,x^0,...,x^7,y^0,...,yaw^7``,
  coefficients in ascending powers of the time since the start of the piece [s]). The
  pieces share uniform breakpoints, are continuous up to the jerk, and are fitted by least
  squares to the planned positions; their number grows until every sample is reproduced
  within ``tolerance_m`` (evaluated with float32 coefficients, as the Crazyflie stores them).
  The Crazyflie keeps trajectories in 4096 bytes of memory, 31 such pieces: longer fits are
  split into ``droneNNN_poly7_partK.csv`` files of at most 31 pieces, with a warning.

Planar runs fly at a constant ``altitude_m``. ``provenance.json`` beside the files records
the versions, seed and scenario hash of the run and of the export, and the fit's accuracy.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from math import factorial
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError
from mpcform.outputs.files import json_safe, provenance
from mpcform.outputs.rundata import RunData

POLY_DEGREE = 7
CONTINUITY = 4  # position, velocity, acceleration and jerk are continuous at breakpoints
CRAZYFLIE_MAX_PIECES = 31  # crazyflie-firmware: TRAJECTORY_MEMORY_SIZE 4096 B / 132 B per poly4d piece
DEFAULT_TOLERANCE_M = 0.02
DEFAULT_ALTITUDE_M = 1.0
MAX_PIECE_S = 2.0  # longest piece tried first [s] (keeps float32 powers of tau modest)
SMOOTHING = 1e-9  # relative weight of the snap integral (regularises pieces with few samples)
SETPOINT_COLUMNS = ("t", "x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "yaw")
POLY_AXES = ("x", "y", "z", "yaw")
POLY_HEADER = ("Duration", *(f"{a}^{m}" for a in POLY_AXES for m in range(POLY_DEGREE + 1)))
PROVENANCE_JSON = "provenance.json"
SPEED_SLACK = 1.1  # warn when the pieces are faster than this times v_max


@dataclass(frozen=True, eq=False)
class PiecewisePolynomial:
    """Polynomial pieces of degree 7 over consecutive intervals starting at ``t0_s``.

    ``coefficients`` (K, m, 8): for piece k and series m, ascending powers of the local time
    ``tau = t - start_k`` [s], ``0 <= tau <= durations_s[k]``.
    """

    t0_s: float
    durations_s: Array  # (K,)
    coefficients: Array  # (K, m, 8)

    @property
    def pieces(self) -> int:
        return int(self.durations_s.shape[0])

    @property
    def breaks_s(self) -> Array:
        """Start of every piece and the end of the last one, (K + 1,) [s]."""
        return self.t0_s + np.concatenate([[0.0], np.cumsum(self.durations_s)])

    def evaluate(self, t_s: object, derivative: int = 0) -> Array:
        """Values (T, m) of the series (or their ``derivative``) at ``t_s`` (T,); clamped to the span."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        breaks = self.breaks_s
        k = np.clip(np.searchsorted(breaks, t, side="right") - 1, 0, self.pieces - 1)
        tau = np.clip(t - breaks[k], 0.0, self.durations_s[k])
        coef = self.coefficients[k]  # (T, m, 8)
        for _ in range(derivative):
            coef = coef[..., 1:] * np.arange(1, coef.shape[-1])
        powers = tau[:, None] ** np.arange(coef.shape[-1])
        return np.einsum("tmc,tc->tm", coef, powers)

    def as_float32(self) -> PiecewisePolynomial:
        """The pieces with durations and coefficients rounded to float32 (Crazyflie storage)."""
        return PiecewisePolynomial(
            self.t0_s,
            self.durations_s.astype(np.float32).astype(float),
            self.coefficients.astype(np.float32).astype(float),
        )


def fit_piecewise_polynomial(t_s: Array, values: Array, pieces: int) -> PiecewisePolynomial:
    """Least-squares fit of ``values`` (T, m) at ``t_s`` (T,) by ``pieces`` uniform degree-7 pieces.

    Continuity of the value and its first three derivatives is imposed at every breakpoint
    (equality constraints, solved with the KKT system); a tiny snap penalty keeps pieces with
    few samples well posed. All m series share the breakpoints and one factorisation.
    """
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(values, dtype=float).reshape(t.shape[0], -1)
    if pieces < 1 or t.shape[0] < 2:
        raise ValidationError("pieces", f"expected >= 1 piece and >= 2 samples, got {pieces}, {t.shape[0]}")
    span = float(t[-1] - t[0])
    h = span / pieces
    nc = POLY_DEGREE + 1
    k = np.minimum(((t - t[0]) / h).astype(int), pieces - 1)
    sigma = (t - t[0]) / h - k  # normalised local time in [0, 1]
    vander = sigma[:, None] ** np.arange(nc)
    size = pieces * nc
    gram = np.zeros((size, size))
    rhs = np.zeros((size, y.shape[1]))
    snap = _snap_gram()
    for piece in range(pieces):
        rows = k == piece
        sl = slice(piece * nc, (piece + 1) * nc)
        v = vander[rows]
        gram[sl, sl] = v.T @ v + SMOOTHING * max(1, int(rows.sum())) * snap
        rhs[sl] = v.T @ y[rows]
    constraints = np.zeros(((pieces - 1) * CONTINUITY, size))
    end_row = np.array([[_falling(m, r) for m in range(nc)] for r in range(CONTINUITY)])
    start_row = np.array([[factorial(r) if m == r else 0.0 for m in range(nc)] for r in range(CONTINUITY)])
    for b in range(pieces - 1):
        rows_b = slice(b * CONTINUITY, (b + 1) * CONTINUITY)
        constraints[rows_b, b * nc : (b + 1) * nc] = end_row
        constraints[rows_b, (b + 1) * nc : (b + 2) * nc] = -start_row
    kkt = np.block([[gram, constraints.T], [constraints, np.zeros((constraints.shape[0],) * 2)]])
    full_rhs = np.vstack([rhs, np.zeros((constraints.shape[0], y.shape[1]))])
    try:
        sol = np.linalg.solve(kkt, full_rhs)
    except np.linalg.LinAlgError:
        sol = np.linalg.lstsq(kkt, full_rhs, rcond=None)[0]
    normalised = sol[:size].reshape(pieces, nc, -1).transpose(0, 2, 1)  # (K, m, 8) in sigma
    coefficients = normalised / h ** np.arange(nc)  # powers of tau = h sigma
    return PiecewisePolynomial(float(t[0]), np.full(pieces, h), coefficients)


@dataclass(frozen=True)
class PolynomialFit:
    """Pieces for all drones (series ``drone * d + axis``) and the worst position error [m]."""

    polynomial: PiecewisePolynomial
    max_error_m: float
    tolerance_m: float

    @property
    def within_tolerance(self) -> bool:
        return self.max_error_m <= self.tolerance_m


def fit_positions(
    t_s: Array, positions_m: Array, tolerance_m: float = DEFAULT_TOLERANCE_M, max_piece_s: float = MAX_PIECE_S
) -> PolynomialFit:
    """Fewest uniform pieces, none longer than ``max_piece_s``, that reproduce every drone's sampled
    positions (T, n, d) within ``tolerance_m`` with float32 coefficients.

    The count grows by half until the fit is within tolerance, then is bisected down. It stops
    at two samples per piece; the result then says it is not within tolerance.
    """
    tol = positive("tolerance", tolerance_m)
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(positions_m, dtype=float)
    flat = p.reshape(p.shape[0], -1)

    def attempt(pieces: int) -> PolynomialFit:
        poly = fit_piecewise_polynomial(t, flat, pieces)
        err = poly.as_float32().evaluate(t).reshape(p.shape) - p
        return PolynomialFit(poly, float(np.linalg.norm(err, axis=-1).max()), tol)

    cap = max(1, (t.shape[0] - 1) // 2)
    span = float(t[-1] - t[0])
    pieces = min(cap, max(1, math.ceil(span / positive("max_piece", max_piece_s) - 1e-9)))
    failed = pieces - 1  # the largest count known (or taken) to fail
    fit = attempt(pieces)
    while not fit.within_tolerance and pieces < cap:
        failed, pieces = pieces, min(cap, max(pieces + 1, math.ceil(1.5 * pieces)))
        fit = attempt(pieces)
    while fit.within_tolerance and pieces - failed > 1:
        mid = (failed + pieces) // 2
        trial = attempt(mid)
        if trial.within_tolerance:
            pieces, fit = mid, trial
        else:
            failed = mid
    return fit


@dataclass(frozen=True)
class ExportResult:
    """Files written, the fit, and warnings for the user (too many pieces, below the floor)."""

    directory: Path
    files: tuple[Path, ...]
    fit: PolynomialFit
    files_per_drone: int
    warnings: tuple[str, ...]


def setpoints(run: RunData, altitude_m: float | None = None) -> tuple[Array, Array, Array]:
    """Positions, velocities and accelerations (T, n, 3) of the planned path (z = altitude if planar)."""
    p = _positions_3d(run, altitude_m)
    vel = np.zeros_like(p)  # planar: vz = az = 0 exactly
    vel[..., : run.dim] = np.gradient(run.positions_m, run.t_s, axis=0, edge_order=1)
    acc = np.zeros_like(p)
    acc[..., : run.dim] = np.gradient(vel[..., : run.dim], run.t_s, axis=0, edge_order=1)
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
    pos, vel, acc = setpoints(run, altitude_m)
    for stale in [*out.glob("drone*_setpoints.csv"), *out.glob("drone*_poly7*.csv")]:
        stale.unlink()  # an earlier export (perhaps split into more parts) of this directory
    t = run.t_s
    fit = fit_positions(t, run.positions_m, tolerance_m, max_piece_s)  # planar: z is exact
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
        "altitude_m": None if run.dim == 3 else _altitude(run, altitude_m),
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


def max_speed(poly: PiecewisePolynomial, n: int, per_piece: int = 50) -> float:
    """Largest speed [m/s] of ``n`` drones' pieces (series drone * d + axis), sampled finely."""
    t = np.linspace(poly.breaks_s[0], poly.breaks_s[-1], per_piece * poly.pieces + 1)
    vel = poly.evaluate(t, derivative=1).reshape(t.shape[0], n, -1)
    return float(np.linalg.norm(vel, axis=-1).max())


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


def _altitude(run: RunData, altitude_m: float | None) -> float:
    return DEFAULT_ALTITUDE_M if altitude_m is None else positive("altitude", altitude_m)


def _positions_3d(run: RunData, altitude_m: float | None) -> Array:
    p = run.positions_m
    if run.dim == 3:
        if altitude_m is not None:
            raise ValidationError("altitude", "applies only to planar runs; a spatial run exports its own z")
        return p.copy()
    z = np.full((*p.shape[:2], 1), _altitude(run, altitude_m))
    return np.concatenate([p, z], axis=-1)


def _falling(m: int, r: int) -> float:
    """r-th derivative of sigma^m at sigma = 1: m! / (m - r)! (0 when r > m)."""
    return float(factorial(m) // factorial(m - r)) if r <= m else 0.0


def _snap_gram() -> Array:
    """Integral over [0, 1] of the products of the 4th derivatives of sigma^m and sigma^l (max 1)."""
    nc = POLY_DEGREE + 1
    gram = np.zeros((nc, nc))
    for m in range(4, nc):
        for ell in range(4, nc):
            gram[m, ell] = _falling(m, 4) * _falling(ell, 4) / (m + ell - 7)
    return gram / gram.max()


def _str_or_none(value: Any) -> Path | None:
    return None if value is None else Path(str(value))
