"""Flight-ready exports of a run: rest-to-rest polynomials, setpoints and Crazyswarm2 files.

For every drone of a run (:class:`~mpcform.outputs.rundata.RunData`, in memory after
``mpcform run --export`` or read back by :func:`~mpcform.outputs.rundata.load_run`):

1. the planned positions (planar runs at ``altitude_m``, then shifted by ``offset_m``) are
   retimed with one time scaling ``s(t)`` for the whole swarm, from rest to rest, within the
   speed, acceleration and jerk limits (:mod:`mpcform.outputs.flight.retime`);
2. the retimed positions are fitted by 7th-order pieces continuous up to the jerk, at rest at
   both ends (:mod:`mpcform.outputs.flight.polynomial`); every planned sample, at its retimed time, is
   within ``tolerance_m`` of the float32 pieces;
3. the pieces are checked: lowest point against ``floor_m`` (refused below it), speed,
   acceleration, jerk, body rate and thrust against :class:`FlightLimits` (refused unless
   ``allow_limits``), and the pairwise separation against the run's ``d_min``, as planned, as
   retimed and as flown on the quadrotor plant (refused unless ``allow_unsafe``);
4. files: ``droneNNN_poly7.csv`` (Crazyswarm ``uav_trajectories`` format: ``Duration,x^0..x^7,
   y^0..,z^0..,yaw^0..yaw^7``, ascending powers of the time since the piece's start; split into
   ``_partK`` files above the Crazyflie's 31 pieces), ``droneNNN_setpoints.csv`` (the pieces
   resampled at ``rate_hz``: ``t, x, y, z, vx, vy, vz, ax, ay, az, yaw, omega_x, omega_y,
   omega_z``, every column a derivative of the pieces; omega the body rates from flatness, what
   ``cmdFullState(pos, vel, acc, yaw, omega)`` takes), ``crazyflies.yaml`` and ``fly.py``
   (:mod:`mpcform.outputs.flight.crazyswarm`) and ``provenance.json``.

Yaw is 0, or with ``yaw="formation"`` the formation's rotation about z (:mod:`mpcform.outputs.flight.yaw`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError
from mpcform.outputs.files import json_safe, provenance
from mpcform.outputs.flight import crazyswarm
from mpcform.outputs.flight.check import FlightCheck, fly_export, fly_export_crazyflow
from mpcform.outputs.flight.files import (
    CRAZYFLIE_MAX_PIECES,
    POLY_HEADER,
    SETPOINT_COLUMNS,
    read_poly,
    read_setpoints,
    write_phase,
)
from mpcform.outputs.flight.limits import FlightEnvelope, FlightLimits, envelope, flat_state
from mpcform.outputs.flight.phases import Flight, phase_record, whole_flight
from mpcform.outputs.flight.pieces import (
    CHECK_RATE_HZ,
    DEFAULT_RATE_HZ,
    check_samples,
    join,
    phase_pieces,
)
from mpcform.outputs.flight.polynomial import (
    DEFAULT_TOLERANCE_M,
    MAX_PIECE_S,
    PolynomialFit,
)
from mpcform.outputs.flight.retime import Retiming
from mpcform.outputs.flight.safety import ObstacleCheck, closest_pair, obstacle_breaches, separation_breaches
from mpcform.outputs.flight.yaw import formation_yaw
from mpcform.outputs.rundata import RunData
from mpcform.world.limits import PLATFORM_TRACKING_M, Limits

DEFAULT_ALTITUDE_M = 1.0
PROVENANCE_JSON = "provenance.json"
YAW_MODES = ("zero", "formation")
__all__ = [
    "POLY_HEADER",
    "SETPOINT_COLUMNS",
    "ExportOptions",
    "ExportResult",
    "export_run",
    "read_poly",
    "read_setpoints",
]


@dataclass(frozen=True)
class ExportOptions:
    """How to export: planar altitude [m], offset [m], floor [m], fit tolerance [m], longest
    piece [s], setpoint rate [Hz], yaw mode, limits (errors unless ``allow_limits``); pairs closer
    than d_min are errors unless ``allow_unsafe`` (:mod:`mpcform.outputs.flight.safety`)."""

    altitude_m: float | None = None
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    floor_m: float = 0.0
    tolerance_m: float = DEFAULT_TOLERANCE_M
    max_piece_s: float = MAX_PIECE_S
    rate_hz: float = DEFAULT_RATE_HZ
    yaw: str = "zero"
    limits: FlightLimits = field(default_factory=FlightLimits)
    allow_limits: bool = False
    allow_untracked: bool = False  # export a run planned without a tracking allowance
    allow_unsafe: bool = False  # export a flight whose drones come closer than d_min
    fly: bool = True  # fly the export on the quadrotor plant (skipped without drone-models)
    crazyflow: bool = False  # also fly it open loop in crazyflow (needs the extra)
    ground_m: tuple[tuple[float, float], ...] | None = None  # pads (x, y) [m]; None: mpcform's layout
    ground_robots: tuple[tuple[str, str], ...] | None = None  # (name, uri) of the robot on each pad

    def __post_init__(self) -> None:
        positive("tolerance", self.tolerance_m)
        positive("rate", self.rate_hz)
        if self.altitude_m is not None:
            positive("altitude", self.altitude_m)
        if not np.isfinite(self.floor_m):
            raise ValidationError("floor", f"expected a finite height [m], got {self.floor_m}")
        if len(self.offset_m) != 3 or not np.all(np.isfinite(self.offset_m)):
            raise ValidationError("offset", f"expected three finite numbers X,Y,Z, got {self.offset_m!r}")
        if self.ground_m is not None:
            _check_pads(self.ground_m)
        if self.ground_robots is not None and (
            self.ground_m is None or len(self.ground_robots) != len(self.ground_m)
        ):
            raise ValidationError("ground", "expected a (name, uri) for each pad of ground_m")
        if self.yaw not in YAW_MODES:
            raise ValidationError("yaw", f"expected one of {', '.join(YAW_MODES)}, got {self.yaw!r}")


def _check_pads(pads: object) -> None:
    """Refuse pads that are not a non-empty list of finite ``(x, y)`` [m]."""
    try:
        xy = np.asarray(pads, dtype=float)
    except (TypeError, ValueError):  # ragged or not numbers
        xy = np.empty((0, 0))
    if not (xy.ndim == 2 and xy.shape[0] and xy.shape[1] == 2 and np.all(np.isfinite(xy))):
        raise ValidationError("ground", f"expected pads of two finite numbers x, y, got {pads!r}")


@dataclass(frozen=True)
class ExportResult:
    """Files written, the fit (error against the planned samples), the retiming, the flight
    envelope and warnings for the user."""

    directory: Path
    files: tuple[Path, ...]
    fit: PolynomialFit
    files_per_drone: int
    warnings: tuple[str, ...]
    retiming: Retiming
    envelope: FlightEnvelope
    min_separation_m: float
    record: dict[str, Any]
    flight: FlightCheck | None
    phases: Flight


def positions_3d(run: RunData, options: ExportOptions) -> Array:
    """Planned positions (T, n, 3) [m]: planar runs at the altitude, then shifted by the offset."""
    p = run.trajectory.positions_m
    if run.dim == 3:
        if options.altitude_m is not None:
            raise ValidationError(
                "altitude", "applies only to planar runs; shift a spatial run with --offset X,Y,Z"
            )
        p3 = p.copy()
    else:
        alt = DEFAULT_ALTITUDE_M if options.altitude_m is None else options.altitude_m
        p3 = np.concatenate([p, np.full((*p.shape[:2], 1), alt)], axis=-1)
    return p3 + np.asarray(options.offset_m, dtype=float)


def export_run(
    run: RunData,
    out_dir: str | Path,
    options: ExportOptions | None = None,
    *,
    before_writing: Callable[[], object] | None = None,
    **fields: Any,
) -> ExportResult:
    """Retime, fit, check and write every drone's files (``fields`` override ``options``).
    ``before_writing`` is called once every check passed, just before the first file is written
    (``mpcform export`` removes its earlier export then); ``out_dir`` must then hold no drone's
    files (an earlier export is never mixed in, nor removed here)."""
    opts = replace(options or ExportOptions(), **fields)
    lim = opts.limits
    if not opts.allow_untracked:
        check_tracked(run.d_min_m, run.n, run.tracking_m)
    out = Path(out_dir)
    dt = float(np.median(np.diff(run.trajectory.t_s)))
    phase_limits = Limits(
        run.v_max_mps or lim.max_speed_mps,
        run.d_min_m,
        tracking_m=run.tracking_m,
        downwash_kappa=run.downwash_kappa,
    )
    metric = run.downwash_metric
    mission_m = positions_3d(run, opts)
    _check_floor(mission_m, run.trajectory.t_s - run.trajectory.t_s[0], opts.floor_m)  # as planned
    pads = None if opts.ground_m is None else np.asarray(opts.ground_m, dtype=float)
    flight = whole_flight(mission_m, dt, phase_limits, lim, opts.floor_m, pads)
    n = run.n
    yaw: Array = np.zeros(flight.positions_m.shape[0])
    mission = dict(flight.phases)["mission"]
    if opts.yaw == "formation":  # held through the ascent and the descent
        samples = np.arange(mission.start, mission.stop)
        mission_yaw = formation_yaw(run.trajectory.positions_m, run.formation.offsets_m)
        yaw = np.interp(np.arange(yaw.shape[0]), samples, mission_yaw)
    parts = [
        phase_pieces(
            name, flight.positions_m[k], dt, yaw[k], lim, opts.tolerance_m, opts.max_piece_s, opts.rate_hz
        )
        for name, k in flight.phases
    ]
    main = next(p for p in parts if p.name == "mission")
    fit, timing = main.fit, main.timing
    flown = join(parts)
    check_samples(flown.duration_s, n, opts.rate_hz)
    t_check = np.linspace(0.0, flown.duration_s, int(np.ceil(CHECK_RATE_HZ * flown.duration_s)) + 1)
    state = flat_state(flown, t_check, n)
    _check_floor(state["pos"], t_check, opts.floor_m)
    env = envelope(t_check, state["vel"], state["acc"], state["jerk"], state["omega"])
    worst = max(parts, key=lambda p: p.fit.max_error_m).fit
    warnings = _warnings(worst, env, opts)
    obstacles = ObstacleCheck(run.obstacles, run.dim, np.asarray(opts.offset_m)) if run.obstacles else None
    check = (
        fly_export(flown, n, opts.tolerance_m, dt, lim.max_acc_mps2, run.d_min_m, metric, obstacles)
        if opts.fly
        else None
    )
    cf = (
        fly_export_crazyflow(flown, n, opts.tolerance_m, run.d_min_m, metric, obstacles)
        if opts.crazyflow
        else None
    )
    if opts.crazyflow and cf is None:
        raise ValidationError(
            "crazyflow", 'flying an export in crazyflow needs it: pip install -e ".[crazyflow]"'
        )
    retimed = closest_pair(t_check, state["pos"], metric)
    planned = [closest_pair(p.dense_t_s, p.dense_m, metric) for p in parts]
    breaches = separation_breaches(
        run.d_min_m,
        opts.tolerance_m,
        min((c for c in planned if c is not None), key=lambda c: c.distance_m, default=None),
        retimed,
        None if check is None else check.closest,
    )
    if obstacles is not None:  # the retimed pieces and the flight check's true path
        retimed_ob = obstacles.approach(t_check, state["pos"])
        breaches += obstacle_breaches(opts.tolerance_m, retimed_ob, None if check is None else check.obstacle)
    if cf is not None and not cf.within_tolerance:
        breaches += [f"flown open loop in crazyflow: {cf.describe()}"]
    if breaches and not opts.allow_unsafe:  # before any file is written
        raise ValidationError("separation", f"{breaches[0]} (--allow-unsafe to export anyway)")
    warnings += breaches
    min_sep = float("inf") if retimed is None else retimed.distance_m
    split = [p for p in parts if p.flown.pieces > CRAZYFLIE_MAX_PIECES]
    per_drone = max(math.ceil(p.flown.pieces / CRAZYFLIE_MAX_PIECES) for p in parts)  # files per phase
    if split:
        warnings.append(
            ", ".join(f"the {p.name}'s {p.flown.pieces} pieces" for p in split)
            + f" per drone exceed the Crazyflie's {CRAZYFLIE_MAX_PIECES}: split into files per "
            "drone (fly.py refuses them), or raise --tolerance"
        )
    if before_writing is not None:
        before_writing()
    out.mkdir(parents=True, exist_ok=True)
    if stale := min([*out.glob("drone*_setpoints.csv"), *out.glob("drone*_poly7*.csv")], default=None):
        raise ValidationError(
            str(stale),
            "a file of an earlier export (perhaps split into other parts); expected a directory "
            "without drones' files: remove them, or export elsewhere (`mpcform export` replaces its own)",
        )
    width = max(3, len(str(n - 1)))
    stems = [f"drone{i:0{width}d}" for i in range(n)]
    files: list[Path] = []
    for part in parts:
        files += write_phase(out, stems, part, opts.rate_hz)
    phases = [(p.name, p.flown.duration_s) for p in parts]
    files += crazyswarm.write_files(out, stems, flight, phases, opts.ground_robots)
    if check is not None and check.max_error_m > check.declared_tolerance_m:
        warnings.append(
            f"flown on the quadrotor plant, drone {check.error_drone} is {check.max_error_m:.3g} m off "
            f"at t = {check.error_t_s:.2f} s, beyond the declared {check.declared_tolerance_m:.3g} m"
        )
    record = _record(run, opts, fit, timing, main.min_time_s, env, min_sep, per_drone, warnings)
    record["max_fit_error_m"] = worst.max_error_m  # of every phase
    record["phases"] = phase_record(flight, parts, lim, metric)
    record["duration_s"] = flown.duration_s  # the trajectories: ascent, mission, descent
    record["flight_duration_s"] = sum(p["duration_s"] for p in record["phases"].values())  # with the legs
    record["quadrotor_flight"] = None if check is None else check.record()
    record["crazyflow_flight"] = None if cf is None else cf.record()
    prov = out / PROVENANCE_JSON
    prov.write_text(json.dumps(json_safe(record), indent=2, allow_nan=False) + "\n")
    files.append(prov)
    return ExportResult(
        out, tuple(files), fit, per_drone, tuple(warnings), timing, env, min_sep, record, check, flight
    )


def check_tracked(d_min_m: float | None, n: int, tracking_m: float) -> None:
    """Refuse (ValidationError ``tracking``) a swarm with ``d_min`` planned without a tracking
    allowance: a real drone's position loop is off its setpoints by up to
    :data:`~mpcform.world.limits.PLATFORM_TRACKING_M`, for which such a plan keeps no room."""
    if d_min_m is not None and n > 1 and tracking_m <= 0.0:
        raise ValidationError(
            "tracking",
            f"the run was planned without a tracking allowance (limits.tracking = 0), so a "
            f"Crazyflie off its setpoints by up to {PLATFORM_TRACKING_M:g} m may come closer than "
            f"d_min = {d_min_m:g} m: run it with --flyable (or set limits.tracking), or pass "
            "--allow-untracked to export it anyway",
        )


def _check_floor(pos: Array, t_s: Array, floor_m: float) -> None:
    j, i = np.unravel_index(int(np.argmin(pos[..., 2])), pos.shape[:2])
    if pos[j, i, 2] < floor_m:
        raise ValidationError(
            "floor",
            f"drone {i} at t = {t_s[j]:.3f} s is at z = {pos[j, i, 2]:.3f} m, below the "
            f"floor {floor_m:g} m: shift the run up with --offset X,Y,Z",
        )


def _warnings(fit: PolynomialFit, env: FlightEnvelope, opts: ExportOptions) -> list[str]:
    warnings: list[str] = []
    if not fit.within_tolerance:
        warnings.append(
            f"the polynomial pieces miss the planned positions by up to {fit.max_error_m:.3g} m "
            f"(tolerance {opts.tolerance_m:g} m)"
        )
    problems = env.violations(opts.limits)
    if problems and not opts.allow_limits:
        raise ValidationError("limits", "; ".join(problems) + " (--allow-limits to export anyway)")
    warnings += problems
    return warnings


def _record(
    run: RunData,
    opts: ExportOptions,
    fit: PolynomialFit,
    timing: Retiming,
    min_time_s: float,
    env: FlightEnvelope,
    min_sep: float,
    parts: int,
    warnings: list[str],
) -> dict[str, Any]:
    prov = run.summary.get("provenance", {})
    scenario_file = prov.get("scenario_file")
    peak = {
        name: {"drone": p.drone, "t_s": p.t_s, "value": p.value}
        for name, p in (
            ("speed_mps", env.speed),
            ("acc_mps2", env.acc),
            ("jerk_mps3", env.jerk),
            ("body_rate_rad_s", env.body_rate),
            ("thrust_per_mass_mps2", env.thrust_acc),
        )
    }
    return {
        "export": provenance(
            int(prov.get("seed") or 0),
            None if scenario_file is None else Path(str(scenario_file)),
            prov.get("scenario_sha256"),
        ),
        "run": prov or None,
        "source": str(run.directory),
        "scenario": run.name,
        "files": {
            "setpoints": "droneNNN_setpoints.csv: "
            + ",".join(SETPOINT_COLUMNS)
            + " [s, m, m/s, m/s^2, rad, rad/s]",
            "polynomials": "droneNNN_poly7[_partK].csv: Crazyswarm uav_trajectories format, "
            "ascending powers of the time since the piece's start [s]",
            "crazyswarm2": f"{crazyswarm.CRAZYFLIES_YAML}, {crazyswarm.FLY_PY}",
        },
        "altitude_m": None if run.dim == 3 else (opts.altitude_m or DEFAULT_ALTITUDE_M),
        "offset_m": list(opts.offset_m),
        "floor_m": opts.floor_m,
        "tracking_m": run.tracking_m,
        "yaw": opts.yaw,
        "setpoint_rate_hz": opts.rate_hz,
        "planned_duration_s": float(run.trajectory.t_s[-1] - run.trajectory.t_s[0]),
        "mission_duration_s": timing.duration_s,
        "mission_min_time_s": min_time_s,
        "pieces": fit.polynomial.pieces,
        "piece_duration_s": float(fit.polynomial.durations_s[0]),
        "files_per_drone": parts,
        "crazyflie_max_pieces": CRAZYFLIE_MAX_PIECES,
        "tolerance_m": opts.tolerance_m,
        "max_fit_error_m": fit.max_error_m,
        "limits": {k: v for k, v in vars(opts.limits).items()},
        "peaks": peak,
        "min_separation_m": min_sep,
        "planned_min_separation_m": getattr(
            closest_pair(run.trajectory.t_s, positions_3d(run, opts), run.downwash_metric), "distance_m", None
        ),
        "d_min_m": run.d_min_m,
        "allow_unsafe": opts.allow_unsafe,
        "warnings": warnings,
    }
