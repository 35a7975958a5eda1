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
import os
import shutil
from importlib.util import find_spec
from pathlib import Path
from typing import Any

from mpcform.cli.export_flags import EXPORT_FIELDS, add_export_options, export_options, report_export
from mpcform.cli.options import option_errors, progress
from mpcform.cli.progress import ProgressBar
from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs.files import DPI_RANGE, FIGURE_DPI, FIGURE_FORMATS, plant_events
from mpcform.outputs.flight.export import check_tracked, export_run
from mpcform.outputs.outdir import EXPORT_DIR, PLOTS_DIR, VIEWER_FILE, DirClaim, claim_dir
from mpcform.outputs.rundata import RunData, formation_data, load_run, write_formation_npz
from mpcform.run.runner import RunResult
from mpcform.scenario.spec import Scenario

PLOT_HINT = "plotting needs matplotlib: pip install 'mpcform[plot]'"
"""The library's names of the export options: their errors name the flag (``--max-speed``)."""


class PlotUnavailable(MPCFormError):
    """matplotlib (or pillow for GIFs) is not installed."""


# ---- run ----------------------------------------------------------------------------------
def add_run_options(cmd: argparse.ArgumentParser) -> None:
    """``--plot``, ``--animate``, ``--export`` (with ``--altitude``, ``--tolerance``) of ``run``."""
    cmd.add_argument("--plot", action="store_true", help="also write the figures into DIR/plots/")
    _add_figure_options(cmd)
    cmd.add_argument("--html", action="store_true", help="also write the interactive viewer, DIR/viewer.html")
    cmd.add_argument(
        "--export",
        action="store_true",
        help="also write per-drone setpoint and polynomial CSVs into DIR/export/",
    )
    add_export_options(cmd)


def progress_bar(scenario: Scenario) -> ProgressBar:
    """The progress callback of a CLI run (draws on a terminal only, after half a second); a
    crazyflow run says first that its simulator is being built and compiled."""
    if scenario.plant.kind == "crazyflow":
        progress("crazyflow: building and compiling the simulator (once per run, about 6 s)")
    return ProgressBar(f"{scenario.name}")


def check_run_options(args: argparse.Namespace, scenario: Scenario) -> None:
    """Fail before simulating when a requested figure cannot be drawn or an option does not apply."""
    check_figure_options(args)
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
    _figures(data, run.out_dir / PLOTS_DIR, args)
    if args.html:
        print(f"wrote {write_view(data, run.out_dir / VIEWER_FILE)}")
    if args.export:
        with option_errors(*EXPORT_FIELDS):
            report_export(export_run(data, run.out_dir / EXPORT_DIR, export_options(args)))


# ---- plot, compare, export ----------------------------------------------------------------
def _plot(args: argparse.Namespace) -> int:
    args.plot = True
    check_figure_options(args)
    data = load_run(args.dir)
    with claim_into(args.dir, PLOTS_DIR, args.out, "plots") as claim:
        claim.clear()
        _figures(data, claim.root / PLOTS_DIR if claim.names else claim.root, args)
    return 0


def _view(args: argparse.Namespace) -> int:
    data = load_run(args.dir)
    default = Path(args.dir) / VIEWER_FILE
    if args.out_file is not None and not _same(Path(args.out_file), default):
        print(f"wrote {write_view(data, Path(args.out_file))}")  # a file the user named: replaced
        return 0
    with claim_dir(args.dir, "run", (VIEWER_FILE,), own=False) as claim:
        claim.clear()
        print(f"wrote {write_view(data, default)}")
    return 0


def claim_into(directory: str, name: str, out: str | None, kind: str) -> DirClaim:
    """The claim of a command writing ``name`` into the run ``directory`` (``plots/``,
    ``export/``), or, with ``--out``, all of a directory of its own (``kind``)."""
    default = Path(directory) / name
    if out is None or _same(Path(out), default):
        return claim_dir(directory, "run", (name,), own=False)
    return claim_dir(out, kind, field="--out")


def _same(a: Path, b: Path) -> bool:
    return a.resolve() == b.resolve()


def write_view(data: RunData, path: Path) -> Path:
    """The interactive viewer of a run (:mod:`mpcform.outputs.viewer`): one self-contained HTML file
    (``run --html`` and ``view`` both from the run's data, the geofence from ``formation.npz``)."""
    from mpcform.formation.geometry import formation_edges
    from mpcform.outputs.viewer import flown_curves, viewer_curves, write_viewer_html

    traj = data.trajectory
    return write_viewer_html(
        path,
        t_s=traj.t_s,
        positions_m=traj.positions_m,
        d_min_m=data.d_min_m,
        v_max_mps=data.v_max_mps,
        edges=formation_edges(data.formation.offsets_m),
        obstacles=data.formation.obstacles,
        geofence=None if data.formation.geofence_m is None else tuple(data.formation.geofence_m),
        reference_m=traj.reference_m,
        title=data.label,
        curves=viewer_curves(
            traj.t_s, traj.positions_m, reference_m=traj.reference_m, commands_mps=traj.commands_mps
        )
        | ({} if data.flown is None else flown_curves(traj.t_s, data.flown)),
        flown=data.flown,
        wind=data.wind,
        events=plant_events(data.summary.get("plant") or {}),
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

        figure = args.figure or default_compare_figure(args.dirs)
        path = compare_runs(runs, figure, run_labels(runs))
        print(f"wrote {path}")
    return 0


def default_compare_figure(dirs: list[str]) -> Path:
    """``compare.png`` in the runs' common parent directory (not the current one)."""
    parents = [str(Path(d).resolve().parent) for d in dirs]
    return Path(os.path.commonpath(parents)) / "compare.png"


def _export(args: argparse.Namespace) -> int:
    data = load_run(args.dir)
    with claim_into(args.dir, EXPORT_DIR, args.out, "export") as claim, option_errors(*EXPORT_FIELDS):
        out = claim.root / EXPORT_DIR if claim.names else claim.root
        report_export(export_run(data, out, export_options(args), before_writing=claim.clear))
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
    _add_figure_options(plot)
    view = sub.add_parser(
        "view",
        help="the interactive viewer of a saved run: one self-contained HTML file",
        description="Write DIR/viewer.html: drones over time in 2-D or 3-D, a time slider, "
        "play/pause at real time, formation edges, obstacles, the geofence, pairs below "
        "d_min, and the metric curves with a cursor linked to the time.",
    )
    view.set_defaults(func=_view)
    view.add_argument("dir", metavar="DIR", help="output directory of `mpcform run`")
    view.add_argument(
        "--out", dest="out_file", metavar="HTML", help="file to write (default: DIR/viewer.html)"
    )

    compare = sub.add_parser(
        "compare",
        help="several saved runs on one figure and one markdown table",
        description="Compare saved runs (e.g. controllers or solvers on one "
        "scenario): a markdown table of their metrics and one figure.",
    )
    compare.set_defaults(func=_compare)
    compare.add_argument("dirs", nargs="+", metavar="DIR", help="output directories of `mpcform run`")
    compare.add_argument(
        "--figure",
        metavar="PNG",
        help="figure path (default: compare.png beside the runs, in their common parent directory)",
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
    add_export_options(export)


def require_plotting(gif: bool = False) -> None:
    """Raise :class:`PlotUnavailable` when matplotlib (or pillow, for a GIF) is missing."""
    if find_spec("matplotlib") is None:
        raise PlotUnavailable(PLOT_HINT)
    try:
        import matplotlib  # noqa: F401 - it reads MPLBACKEND as it loads
    except ValueError:
        backend = os.environ.get("MPLBACKEND", "")
        raise ValidationError(
            "MPLBACKEND", f"{backend!r} is not a matplotlib backend; expected one it knows (Agg), or unset it"
        ) from None
    if gif and find_spec("PIL") is None:
        raise PlotUnavailable("the GIF writer needs pillow: pip install 'mpcform[plot]'")


# ---- helpers ------------------------------------------------------------------------------
def _add_figure_options(cmd: argparse.ArgumentParser) -> None:
    cmd.add_argument(
        "--animate",
        nargs="?",
        const="auto",
        choices=("gif", "mp4", "auto"),
        help="also write the flight as a video, DIR/plots/flight.gif or .mp4 (ffmpeg); "
        "alone: mp4 when ffmpeg is installed, else gif",
    )
    cmd.add_argument(
        "--speed",
        type=float,
        default=1.0,
        metavar="X",
        help="real-time factor of the video (default 1: as long as the flight)",
    )
    cmd.add_argument("--format", choices=FIGURE_FORMATS, default="png", help="figure files (default png)")
    cmd.add_argument("--dpi", type=int, default=FIGURE_DPI, help=f"figure resolution (default {FIGURE_DPI})")


def check_figure_options(args: argparse.Namespace) -> None:
    """Before any work: plotting installed for what is asked, ``--speed`` a positive real-time
    factor with ``--animate``, ``--dpi`` and ``--format`` with figures, an MP4 with ffmpeg."""
    if args.plot or args.animate:
        require_plotting(gif=args.animate in ("gif", "auto"))
    if not args.speed > 0 or args.speed == float("inf"):
        raise ValidationError("--speed", f"expected a positive real-time factor, got {args.speed}")
    if args.speed != 1.0 and not args.animate:
        raise ValidationError("--speed", "applies only with --animate")
    if not DPI_RANGE[0] <= args.dpi <= DPI_RANGE[1]:
        raise ValidationError(
            "--dpi", f"expected an integer in {DPI_RANGE[0]}..{DPI_RANGE[1]}, got {args.dpi}"
        )
    if (args.format != "png" or args.dpi != FIGURE_DPI) and not args.plot:
        raise ValidationError("--format" if args.format != "png" else "--dpi", "applies only with --plot")
    if args.animate == "mp4" and shutil.which("ffmpeg") is None:
        raise ValidationError("--animate", "an MP4 needs ffmpeg on the PATH; ask for --animate gif")


def _figures(data: RunData, out: Path, args: argparse.Namespace) -> None:
    if not (args.plot or args.animate):
        return
    if args.plot:
        from mpcform.outputs.figures import plot_run  # imported only when figures are asked for

        paths = plot_run(data, out, args.format, args.dpi)
        print(f"wrote {len(paths)} figures ({', '.join(p.name for p in paths)}) to {out}")
    if args.animate:
        from mpcform.outputs.animation import animate_run, animation_file

        bar = ProgressBar("animating")
        try:
            path = animate_run(data, out / animation_file(args.animate), speed=args.speed, progress=bar)
        finally:
            bar.close()
        print(f"wrote {path}")
