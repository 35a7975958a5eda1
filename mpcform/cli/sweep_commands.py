"""The ``sweep`` subcommand of ``mpcform`` (wired in by :mod:`mpcform.cli.main`): one scenario over
seeds and parameter values, run by :mod:`mpcform.run.sweep`."""

from __future__ import annotations

import argparse

from mpcform.cli.options import add_max_memory, print_bench, progress, solver_help

SWEEP_HELP = "run a scenario over seeds and parameter values in parallel"
SWEEP_DESCRIPTION = (
    "Run one scenario file over a grid of seeds and parameter values (the Cartesian product of "
    "--seeds and every --set list), in worker processes or on a dask cluster, and print one "
    "markdown row per parameter combination: success rate over the seeds, separation, tracking "
    "errors, fallbacks and step times, then the failed runs. A run succeeds when it raised "
    "nothing, kept d_min (also along the straight segments) and v_max, and ended within --tol of "
    "its reference. Every combination is validated before the first run."
)


def _sweep(args: argparse.Namespace) -> int:
    from mpcform.run import sweep

    seeds = sweep.parse_seeds(args.seeds) if args.seeds else None
    sets = [sweep.parse_set(text) for text in args.set]
    jobs = sweep.build_jobs(args.scenario, seeds, sets, args.solver, args.tol)

    def report(done: int, total: int) -> None:
        progress(f"sweep: {done}/{total} runs")

    records = sweep.run_sweep(
        jobs, args.jobs, args.executor, args.scheduler, progress=report, max_memory_gib=args.max_memory
    )
    groups = sweep.aggregate(records)
    failed = sweep.failures_text(records)
    print_bench(
        sweep.markdown_table(groups) + (f"\n\nfailed runs:\n{failed}" if failed else ""),
        groups + records,
        args.json,
    )
    return 0


def add_sweep(sub: argparse._SubParsersAction) -> None:
    """``sweep``."""
    from mpcform.run.sweep import DEFAULT_TOLERANCE_M, EXECUTORS

    cmd = sub.add_parser("sweep", help=SWEEP_HELP, description=SWEEP_DESCRIPTION)
    cmd.set_defaults(func=_sweep)
    cmd.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
    cmd.add_argument("--seeds", metavar="SPEC", help="seeds, e.g. 0..19 or 0,3,7 (default: the file's)")
    cmd.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=V1,V2",
        help="a dotted scenario key and its values, e.g. controller.horizon=5,10",
    )
    cmd.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes")
    cmd.add_argument("--solver", metavar="NAME", help=solver_help("override controller.solver (mpc)"))
    cmd.add_argument(
        "--tol",
        type=float,
        default=DEFAULT_TOLERANCE_M,
        metavar="M",
        help="final tracking error of a successful run [m] (>= 0)",
    )
    cmd.add_argument("--executor", default="process", choices=EXECUTORS, help="process pool or dask cluster")
    cmd.add_argument("--scheduler", metavar="ADDRESS", help="dask scheduler (default: a local cluster)")
    cmd.add_argument("--json", metavar="PATH", help="also write groups and runs as a JSON list of records")
    add_max_memory(cmd, "run (each run of the sweep)")
