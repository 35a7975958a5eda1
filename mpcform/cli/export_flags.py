"""The export's command-line flags (``run --export`` and ``export``): parsing them into
:class:`~mpcform.outputs.flight.export.ExportOptions`, and the report of what was written."""

from __future__ import annotations

import argparse
import sys

from mpcform.outputs.flight.crazyswarm import read_pads
from mpcform.outputs.flight.export import (
    CRAZYFLIE_MAX_PIECES,
    DEFAULT_RATE_HZ,
    YAW_MODES,
    ExportOptions,
    ExportResult,
)
from mpcform.outputs.flight.limits import FlightLimits, platform_thrust_acc_mps2
from mpcform.outputs.flight.polynomial import DEFAULT_TOLERANCE_M

EXPORT_FIELDS = (
    "altitude offset floor tolerance rate max_speed max_acc max_jerk max_body_rate crazyflow ground".split()
)
"""The library's fields that are export flags (their errors name ``--max-speed``, not ``max_speed``)."""


def add_export_options(cmd: argparse.ArgumentParser) -> None:
    cmd.add_argument(
        "--altitude", type=float, metavar="M", help="flight altitude of a planar run [m] (default 1)"
    )
    cmd.add_argument(
        "--tolerance",
        type=float,
        default=DEFAULT_TOLERANCE_M,
        metavar="M",
        help=f"largest distance between the polynomials and the planned positions [m] "
        f"(default {DEFAULT_TOLERANCE_M:g}); raise it for fewer pieces",
    )
    cmd.add_argument(
        "--offset",
        type=_offset,
        default=(0.0, 0.0, 0.0),
        metavar="X,Y,Z",
        help="shift the exported positions [m] (e.g. 0,0,2.5 lifts a spatial run)",
    )
    cmd.add_argument(
        "--floor",
        type=float,
        default=0.0,
        metavar="M",
        help="refuse an export whose lowest point is below this height [m]",
    )
    cmd.add_argument(
        "--ground",
        metavar="YAML",
        help="a Crazyswarm2 crazyflies.yaml: take off from and land on its robots' initial_position "
        "(default: the start formation below itself, or a grid mpcform chooses)",
    )
    cmd.add_argument(
        "--rate",
        type=float,
        default=DEFAULT_RATE_HZ,
        metavar="HZ",
        help=f"rate of the setpoint CSVs [Hz] (default {DEFAULT_RATE_HZ:g})",
    )
    cmd.add_argument(
        "--yaw",
        choices=YAW_MODES,
        default="zero",
        help="yaw of the drones: zero, or the formation's rotation about z",
    )
    d = FlightLimits()
    flags = (
        ("--max-speed", "max_speed_mps", d.max_speed_mps, "m/s"),
        ("--max-acc", "max_acc_mps2", d.max_acc_mps2, "m/s^2"),
        ("--max-jerk", "max_jerk_mps3", d.max_jerk_mps3, "m/s^3"),
        ("--max-body-rate", "max_body_rate_rad_s", d.max_body_rate_rad_s, "rad/s"),
    )
    for flag, dest, value, unit in flags:
        cmd.add_argument(
            flag,
            dest=dest,
            type=float,
            default=value,
            metavar="X",
            help=f"flight limit [{unit}] (default {value:.3g}, Crazyflie 2.x)",
        )
    cmd.add_argument(
        "--allow-limits",
        action="store_true",
        help="export even when a flight limit is exceeded (then a warning)",
    )
    cmd.add_argument(
        "--allow-untracked",
        action="store_true",
        help="export a run planned without a tracking allowance (run it with --flyable instead)",
    )
    cmd.add_argument(
        "--allow-unsafe",
        action="store_true",
        help="export a flight whose drones come closer than d_min (planned, retimed or flown); "
        "recorded in provenance.json",
    )
    cmd.add_argument(
        "--no-flight-check",
        action="store_true",
        help="do not fly the export on the quadrotor plant (needs drone-models)",
    )
    cmd.add_argument(
        "--crazyflow",
        action="store_true",
        help='also fly the export open loop in crazyflow (pip install -e ".[crazyflow]"): '
        "contacts or pairs closer than d_min refuse it",
    )


def export_options(args: argparse.Namespace) -> ExportOptions:
    """The :class:`ExportOptions` of the command line."""
    limits = FlightLimits(
        args.max_speed_mps,
        args.max_acc_mps2,
        args.max_jerk_mps3,
        args.max_body_rate_rad_s,
        platform_thrust_acc_mps2(),
    )
    pads = None if args.ground is None else read_pads(args.ground)
    return ExportOptions(
        altitude_m=args.altitude,
        offset_m=args.offset,
        floor_m=args.floor,
        tolerance_m=args.tolerance,
        rate_hz=args.rate,
        yaw=args.yaw,
        limits=limits,
        allow_limits=args.allow_limits,
        allow_untracked=args.allow_untracked,
        allow_unsafe=args.allow_unsafe,
        fly=not args.no_flight_check,
        crazyflow=args.crazyflow,
        ground_m=pads[0] if pads else None,
        ground_robots=pads[1] if pads else None,
    )


def _offset(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z (three numbers), got {text!r}")
    return values


def report_export(result: ExportResult) -> None:
    fit, rec, env = result.fit, result.record, result.envelope
    n = result.phases.positions_m.shape[1]
    phases = ", ".join(f"{name} {p['duration_s']:.3g} s" for name, p in rec["phases"].items())
    print(
        f"exported {n} drone{'s' * (n != 1)} to {result.directory}: ground to ground in "
        f"{rec['flight_duration_s']:.2f} s ({phases}; the mission was planned for "
        f"{rec['planned_duration_s']:.2f} s); the mission in {fit.polynomial.pieces} polynomial pieces "
        f"({result.files_per_drone} file{'s' * (result.files_per_drone != 1)} per drone and phase, at most "
        f"{CRAZYFLIE_MAX_PIECES} pieces each), max fit error {fit.max_error_m:.2g} m "
        f"(tolerance {fit.tolerance_m:g} m)"
    )
    print(
        f"  peaks: speed {env.speed.value:.3g} m/s, acceleration {env.acc.value:.3g} m/s^2, jerk "
        f"{env.jerk.value:.3g} m/s^3, body rate {env.body_rate.value:.3g} rad/s; min separation "
        f"{result.min_separation_m:.3g} m; setpoints at {rec['setpoint_rate_hz']:g} Hz; Crazyswarm2: "
        "crazyflies.yaml, fly.py"
    )
    if (cf := rec.get("crazyflow_flight")) is not None:
        print(
            f"  flown open loop in crazyflow: true tracking error {cf['max_tracking_error_m']:.3g} m, "
            f"true min separation {cf['min_separation_m']:.3g} m, no contact"
        )
    if result.flight is not None:
        f = result.flight
        print(
            f"  flown on the quadrotor plant: true tracking error {f.max_error_m:.3g} m (declared "
            f"{f.declared_tolerance_m:.3g} m = margin {f.plant_margin_m:.3g} + fit {f.fit_tolerance_m:g}), "
            f"true min separation {f.min_separation_m:.3g} m"
        )
    for warning in result.warnings:
        print(f"mpcform: warning: {warning}", file=sys.stderr)
