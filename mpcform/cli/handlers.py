"""The scenario runner's commands beyond ``run``: figures, animation, comparison, export, checks.

``mpcform.cli.main`` wires these in; each command is a thin layer over library functions
(:mod:`mpcform.outputs.rundata`, :mod:`mpcform.outputs.figures`, :mod:`mpcform.outputs.animation`,
:mod:`mpcform.outputs.flight.export`, :mod:`mpcform.outputs.compare`, :mod:`mpcform.scenario.check`).
``run --plot/--animate/--export`` draws and exports the run in memory; ``plot``, ``compare`` and
``export`` read saved runs. Plotting is imported only when a figure is asked for, after checking
that matplotlib is installed (else exit 2 with the install hint).
"""

from __future__ import annotations

import argparse
import json
import sys
from importlib.util import find_spec
from pathlib import Path
from typing import Any

from mpcform.cli.options import option_errors
from mpcform.cli.progress import ProgressBar
from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs.flight.export import (
    CRAZYFLIE_MAX_PIECES,
    DEFAULT_RATE_HZ,
    YAW_MODES,
    ExportOptions,
    ExportResult,
    check_tracked,
    export_run,
)
from mpcform.outputs.flight.limits import FlightLimits, platform_thrust_acc_mps2
from mpcform.outputs.flight.polynomial import DEFAULT_TOLERANCE_M
from mpcform.outputs.rundata import RunData, formation_data, load_run, write_formation_npz
from mpcform.run.runner import RunResult
from mpcform.scenario.spec import Scenario

PLOTS_DIR = "plots"
EXPORT_DIR = "export"
VIEWER_FILE = "viewer.html"
PLOT_HINT = "plotting needs matplotlib: pip install 'mpcform[plot]'"
EXPORT_FIELDS = "altitude offset floor tolerance rate max_speed max_acc max_jerk max_body_rate".split()
"""The library's names of the export options: their errors name the flag (``--max-speed``)."""


class PlotUnavailable(MPCFormError):
    """matplotlib (or pillow for GIFs) is not installed."""


# ---- run ----------------------------------------------------------------------------------
def add_run_options(cmd: argparse.ArgumentParser) -> None:
    """``--plot``, ``--animate``, ``--export`` (with ``--altitude``, ``--tolerance``) of ``run``."""
    cmd.add_argument("--plot", action="store_true", help="also write PNG figures into DIR/plots/")
    cmd.add_argument(
        "--animate",
        action="store_true",
        help="also write the flight as a video: DIR/plots/flight.mp4 with ffmpeg, else flight.gif",
    )
    _add_speed_option(cmd)
    cmd.add_argument("--html", action="store_true", help="also write the interactive viewer, DIR/viewer.html")
    cmd.add_argument(
        "--export",
        action="store_true",
        help="also write per-drone setpoint and polynomial CSVs into DIR/export/",
    )
    _add_export_options(cmd)


def progress_bar(scenario: Scenario) -> ProgressBar:
    """The progress callback of a CLI run (draws on a terminal only, after half a second)."""
    return ProgressBar(f"{scenario.name}")


def check_run_options(args: argparse.Namespace, scenario: Scenario) -> None:
    """Fail before simulating when a requested figure cannot be drawn or an option does not apply."""
    if args.plot or args.animate:
        require_plotting(gif=args.animate)
    check_speed(args)
    with option_errors(*EXPORT_FIELDS):
        export_options(args)  # non-finite numbers, before the run
    if args.altitude is not None and not args.export:
        raise ValidationError("--altitude", "applies only with --export")
    if args.altitude is not None and scenario.dim == 3:
        raise ValidationError(
            "--altitude", "applies only to planar scenarios; shift a spatial run with --offset X,Y,Z"
        )
    if args.export and not args.allow_untracked:  # before the run (only the MPC keeps the allowance)
        mpc = (args.controller or scenario.controller.kind) == "mpc"
        check_tracked(scenario.limits.d_min_m, scenario.n, scenario.limits.tracking_m if mpc else 0.0)


def finish_run(args: argparse.Namespace, scenario: Scenario, run: RunResult) -> None:
    """After ``run`` wrote its files: ``formation.npz``, figures, animation and export as asked,
    all from the run and the scenario in memory (nothing is read back)."""
    if run.out_dir is None or not (args.plot or args.animate or args.export or args.html):
        return
    data = RunData(run.simulation, formation_data(scenario, run.simulation.t_s), run.summary, run.out_dir)
    write_formation_npz(run.out_dir, data.formation)
    _figures(data, run.out_dir / PLOTS_DIR, args.plot, args.animate, args.speed)
    if args.html:
        lim = scenario.limits
        fence = None if lim.geofence_min_m is None else (lim.geofence_min_m, lim.geofence_max_m)
        print(f"wrote {write_view(data, run.out_dir / VIEWER_FILE, fence)}")
    if args.export:
        with option_errors(*EXPORT_FIELDS):
            _report_export(export_run(data, run.out_dir / EXPORT_DIR, export_options(args)))


# ---- plot, compare, export ----------------------------------------------------------------
def _plot(args: argparse.Namespace) -> int:
    require_plotting(gif=args.animate)
    check_speed(args)
    data = load_run(args.dir)
    out = Path(args.dir) / PLOTS_DIR if args.out is None else Path(args.out)
    _figures(data, out, True, args.animate, args.speed)
    return 0


def _view(args: argparse.Namespace) -> int:
    data = load_run(args.dir)
    print(f"wrote {write_view(data, Path(args.dir) / VIEWER_FILE if args.out is None else Path(args.out))}")
    return 0


def write_view(data: RunData, path: Path, geofence: tuple[Any, Any] | None = None) -> Path:
    """The interactive viewer of a run (:mod:`mpcform.outputs.viewer`): one self-contained HTML file."""
    from mpcform.formation.geometry import formation_edges
    from mpcform.outputs.viewer import viewer_curves, write_viewer_html

    traj = data.trajectory
    return write_viewer_html(
        path,
        t_s=traj.t_s,
        positions_m=traj.positions_m,
        d_min_m=data.d_min_m,
        v_max_mps=data.v_max_mps,
        edges=formation_edges(data.formation.offsets_m),
        obstacles=data.formation.obstacles,
        geofence=geofence,
        reference_m=traj.reference_m,
        title=data.label,
        curves=viewer_curves(
            traj.t_s, traj.positions_m, reference_m=traj.reference_m, commands_mps=traj.commands_mps
        ),
    )


def _compare(args: argparse.Namespace) -> int:
    from mpcform.outputs.compare import comparison_records, markdown_table, run_labels

    if not args.no_figure:
        require_plotting()
    runs = [load_run(d) for d in args.dirs]
    records = comparison_records(runs)
    print(markdown_table(records))
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=2) + "\n")
    if not args.no_figure:
        from mpcform.outputs.figures import compare_runs

        path = compare_runs(runs, args.figure, run_labels(runs))
        print(f"wrote {path}")
    return 0


def _export(args: argparse.Namespace) -> int:
    data = load_run(args.dir)
    out = Path(args.dir) / EXPORT_DIR if args.out is None else Path(args.out)
    with option_errors(*EXPORT_FIELDS):
        _report_export(export_run(data, out, export_options(args)))
    return 0


def add_commands(sub: Any) -> None:
    """Add ``plot``, ``compare`` and ``export`` to the ``mpcform`` subcommands."""
    plot = sub.add_parser(
        "plot",
        help="draw the figures of a saved run (DIR from `mpcform run --out DIR`)",
        description="Draw the figures of a saved run into DIR/plots/.",
    )
    plot.set_defaults(func=_plot)
    plot.add_argument("dir", metavar="DIR", help="output directory of `mpcform run`")
    plot.add_argument("--out", metavar="OUT", help="figure directory (default: DIR/plots/)")
    plot.add_argument("--animate", action="store_true", help="also write the flight as a video")
    _add_speed_option(plot)
    view = sub.add_parser(
        "view",
        help="the interactive viewer of a saved run: one self-contained HTML file",
        description="Write DIR/viewer.html: drones over time in 2-D or 3-D, a time slider, "
        "play/pause at real time, formation edges, obstacles, the geofence, pairs below "
        "d_min, and the metric curves with a cursor linked to the time.",
    )
    view.set_defaults(func=_view)
    view.add_argument("dir", metavar="DIR", help="output directory of `mpcform run`")
    view.add_argument("--out", metavar="HTML", help="file to write (default: DIR/viewer.html)")

    compare = sub.add_parser(
        "compare",
        help="several saved runs on one figure and one markdown table",
        description="Compare saved runs (e.g. controllers or solvers on one "
        "scenario): a markdown table of their metrics and one figure.",
    )
    compare.set_defaults(func=_compare)
    compare.add_argument("dirs", nargs="+", metavar="DIR", help="output directories of `mpcform run`")
    compare.add_argument(
        "--figure", default="compare.png", metavar="PNG", help="figure path (default: compare.png)"
    )
    compare.add_argument("--no-figure", action="store_true", help="print the table only")
    compare.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")

    export = sub.add_parser(
        "export",
        help="per-drone setpoint CSVs and Crazyswarm polynomial trajectories",
        description="Export a saved run for a flight stack: per drone, a setpoint "
        "CSV (t, position, velocity, acceleration, yaw) and 7th-order polynomial "
        "pieces in the Crazyswarm uav_trajectories CSV format.",
    )
    export.set_defaults(func=_export)
    export.add_argument("dir", metavar="DIR", help="output directory of `mpcform run`")
    export.add_argument("--out", metavar="OUT", help="export directory (default: DIR/export/)")
    _add_export_options(export)


def require_plotting(gif: bool = False) -> None:
    """Raise :class:`PlotUnavailable` when matplotlib (or pillow, for a GIF) is missing."""
    if find_spec("matplotlib") is None:
        raise PlotUnavailable(PLOT_HINT)
    if gif and find_spec("PIL") is None:
        raise PlotUnavailable("the GIF writer needs pillow: pip install 'mpcform[plot]'")


# ---- helpers ------------------------------------------------------------------------------
def _add_export_options(cmd: argparse.ArgumentParser) -> None:
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
        "--no-flight-check",
        action="store_true",
        help="do not fly the export on the quadrotor plant (needs drone-models)",
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
        fly=not args.no_flight_check,
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


def _add_speed_option(cmd: argparse.ArgumentParser) -> None:
    cmd.add_argument(
        "--speed",
        type=float,
        default=1.0,
        metavar="X",
        help="real-time factor of the video (default 1: as long as the flight)",
    )


def check_speed(args: argparse.Namespace) -> None:
    """``--speed`` is a positive real-time factor and applies only with ``--animate``."""
    if not args.speed > 0 or args.speed == float("inf"):
        raise ValidationError("--speed", f"expected a positive real-time factor, got {args.speed}")
    if args.speed != 1.0 and not args.animate:
        raise ValidationError("--speed", "applies only with --animate")


def _figures(data: RunData, out: Path, plot: bool, animate: bool, speed: float = 1.0) -> None:
    if not (plot or animate):
        return
    if plot:
        from mpcform.outputs.figures import plot_run  # imported only when figures are asked for

        paths = plot_run(data, out)
        print(f"wrote {len(paths)} figures ({', '.join(p.name for p in paths)}) to {out}")
    if animate:
        from mpcform.outputs.animation import animate_run, animation_file

        bar = ProgressBar("animating")
        try:
            path = animate_run(data, out / animation_file(), speed=speed, progress=bar)
        finally:
            bar.close()
        print(f"wrote {path}")


def _report_export(result: ExportResult) -> None:
    fit, rec, env = result.fit, result.record, result.envelope
    n = sum(p.name.endswith("_setpoints.csv") for p in result.files)
    print(
        f"exported {n} drone{'s' * (n != 1)} to {result.directory}: rest to rest in "
        f"{result.retiming.duration_s:.2f} s (planned {rec['planned_duration_s']:.2f} s), "
        f"{fit.polynomial.pieces} polynomial pieces of {fit.polynomial.durations_s[0]:.3g} s each "
        f"({result.files_per_drone} file{'s' * (result.files_per_drone != 1)} per drone, at most "
        f"{CRAZYFLIE_MAX_PIECES} pieces each), max fit error {fit.max_error_m:.2g} m "
        f"(tolerance {fit.tolerance_m:g} m)"
    )
    print(
        f"  peaks: speed {env.speed.value:.3g} m/s, acceleration {env.acc.value:.3g} m/s^2, jerk "
        f"{env.jerk.value:.3g} m/s^3, body rate {env.body_rate.value:.3g} rad/s; min separation "
        f"{result.min_separation_m:.3g} m; setpoints at {rec['setpoint_rate_hz']:g} Hz; Crazyswarm2: "
        "crazyflies.yaml, fly.py"
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
