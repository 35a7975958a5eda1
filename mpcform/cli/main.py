"""The ``mpcform`` command: a thin argparse layer over :mod:`mpcform.run.runner`.

Errors in user input print one line ``mpcform: error: <message>`` on stderr and exit with
status 2 (argparse usage errors too); no traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from mpcform.cli import handlers as cli_runner
from mpcform.errors import MPCFormError
from mpcform.outputs.files import OUTPUT_FILES, format_summary
from mpcform.run.runner import run_scenario
from mpcform.scenario.keys import key_reference_markdown
from mpcform.scenario.load import load_scenario
from mpcform.scenario.plant import with_plant_kind
from mpcform.sim.plants import KINDS as PLANT_KINDS
from mpcform.solvers.registry import DEFAULT_SOLVER, PERSISTENT_SOLVERS, solver_infos

EXIT_USAGE = 2


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        raise _UsageError(message)


def _run(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    if args.plant is not None:
        scenario = with_plant_kind(scenario, args.plant)
    cli_runner.check_run_options(args, scenario)  # e.g. --plot without matplotlib: fail before running
    out_dir = Path("results") / scenario.name if args.out is None else Path(args.out)
    run = run_scenario(scenario, out_dir, controller=args.controller, solver=args.solver,
                       progress=cli_runner.progress_bar(scenario))  # fmt: skip
    print(format_summary(run.summary))
    print(f"wrote {', '.join(OUTPUT_FILES)} to {run.out_dir}")
    cli_runner.finish_run(args, scenario, run)  # --plot, --animate, --export
    return 0


def _validate(args: argparse.Namespace) -> int:
    return cli_runner.validate(args)  # every problem of the file, with its line


def _solvers(args: argparse.Namespace) -> int:
    rows = solver_infos()
    width = max(len(r.name) for r in rows)
    print(f"{'solver':<{width}}  installed  usable  warm  persistent  note")
    for r in rows:
        flags = (r.installed, r.usable, r.warm_start, r.persistent)
        yes = [f"{'yes' if f else 'no':<{w}}" for f, w in zip(flags, (9, 6, 4, 10), strict=True)]
        print(f"{r.name:<{width}}  {'  '.join(yes)}  {r.note}")
    return 0


def _keys(args: argparse.Namespace) -> int:
    print(key_reference_markdown(), end="")
    return 0


def _bench_mpc(args: argparse.Namespace) -> int:
    from mpcform.bench import mpc as bench_mpc  # benchmarks are imported only when asked for

    rows = bench_mpc.run(args.n, args.spatial_n, args.steps, args.solver, args.coupling, args.cvxpy_max_n)
    _print_bench(bench_mpc.markdown_table(rows), rows, args.json)
    return 0


def _bench_plant(args: argparse.Namespace) -> int:
    from mpcform.bench import plant as bench_plant

    rows = bench_plant.run(args.n, args.duration, args.rate, args.repeats, wind=not args.no_wind)
    _print_bench(bench_plant.markdown_table(rows), rows, args.json)
    return 0


def _print_bench(table: str, rows: list[dict[str, object]], json_path: str | None) -> None:
    print(table)
    if json_path:
        Path(json_path).write_text(json.dumps(rows, indent=2, default=float) + "\n")


def _add_bench(sub: argparse._SubParsersAction) -> None:
    bench = sub.add_parser("bench", help="benchmarks (markdown table; --json PATH for records)")
    kinds = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    mpc = kinds.add_parser("mpc", help="planner step times vs raw solver, numpy rollout and cvxpy")
    mpc.set_defaults(func=_bench_mpc)
    mpc.add_argument("--n", type=int, nargs="*", default=[8, 16, 32, 64], help="planar swap sizes")
    mpc.add_argument("--spatial-n", type=int, nargs="*", default=[20], help="spatial swap sizes")
    mpc.add_argument("--steps", type=int, default=60, help="closed-loop steps per swap (dt 0.1 s)")
    mpc.add_argument("--solver", default=DEFAULT_SOLVER, choices=PERSISTENT_SOLVERS,
                     help="QP backend (decoupled, solved per drone: of the cvxpy reference only)")
    mpc.add_argument("--coupling", default="joint", choices=("joint", "decoupled", "decoupled-sparse"),
                     help="planner mode (decoupled-sparse: one sparse QP, not per-drone DAQP QPs)")
    mpc.add_argument("--cvxpy-max-n", type=int, default=16, help="largest n also run through cvxpy")
    mpc.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")
    _add_bench_solvers(kinds)
    _add_bench_scale(kinds)
    plant = kinds.add_parser("plant", help="the quadrotor plant alone: n drones, a fixed command sequence")
    plant.set_defaults(func=_bench_plant)
    plant.add_argument("--n", type=int, default=20, help="drones")
    plant.add_argument("--duration", type=float, default=12.0, help="flight time [s]")
    plant.add_argument("--rate", type=float, default=500.0, help="inner-loop rate [Hz]")
    plant.add_argument("--repeats", type=int, default=3, help="runs (median and max are reported)")
    plant.add_argument("--no-wind", action="store_true", help="still air (default: gusts of 0.5 m/s)")
    plant.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")


def _progress(text: str) -> None:
    if sys.stderr.isatty():
        print(text, file=sys.stderr, flush=True)


def _bench_solvers(args: argparse.Namespace) -> int:
    from mpcform.bench import report as bench_report
    from mpcform.bench import solvers as bs

    problems = args.problems or bs.DEFAULT_PROBLEMS_DIR
    bench = bs.run_solver_benchmark(problems, args.solvers, args.settings, args.modes, args.time_limit,
                                    exact=not args.no_exact, progress=_progress)  # fmt: skip
    report = bench_report.markdown_report(bench)
    _print_bench(report, bench_report.records(bench), args.json)
    if args.report:
        Path(args.report).write_text(report + "\n")
    return 0


def _bench_closed_loop(args: argparse.Namespace) -> int:
    from mpcform.bench import closed_loop
    from mpcform.bench.problems import DEFAULT_SCENARIOS

    rows = closed_loop.run_closed_loop(args.scenarios or DEFAULT_SCENARIOS[:2], args.solvers, args.timeout,
                                       args.duration, progress=_progress)  # fmt: skip
    report = closed_loop.closed_loop_markdown(rows)
    _print_bench(report, rows, args.json)
    if args.report:
        Path(args.report).write_text(report)
    return 0


def _add_bench_solvers(kinds: argparse._SubParsersAction) -> None:
    from mpcform.bench.accuracy import SETTINGS
    from mpcform.bench.solvers import DEFAULT_TIME_LIMIT_S
    from mpcform.bench.worker import MODES

    solvers = kinds.add_parser("solvers", help="QP solvers on the recorded problems (problems/)")
    solvers.set_defaults(func=_bench_solvers)
    solvers.add_argument("--problems", metavar="DIR", help="problem directory (default: bundled problems/)")
    solvers.add_argument("--solvers", nargs="+", metavar="NAME", help="backends (default: all known)")
    solvers.add_argument("--settings", nargs="+", choices=list(SETTINGS), default=list(SETTINGS))
    solvers.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    solvers.add_argument("--time-limit", type=float, default=DEFAULT_TIME_LIMIT_S, metavar="S",
                         help="per-solve time limit [s]")  # fmt: skip
    solvers.add_argument("--no-exact", action="store_true", help="skip the casadi:ipopt exact reference")
    loop = kinds.add_parser("closed-loop", help="each solver drives the same scenarios through the planner")
    loop.set_defaults(func=_bench_closed_loop)
    loop.add_argument("scenarios", nargs="*", metavar="SCENARIO", help="scenario files (default: the swaps)")
    loop.add_argument("--solvers", nargs="+", metavar="NAME", help="backends (default: all usable)")
    loop.add_argument("--timeout", type=float, default=600.0, metavar="S", help="time limit per run [s]")
    loop.add_argument("--duration", type=float, metavar="S", help="override the scenarios' duration [s]")
    for cmd in (solvers, loop):
        cmd.add_argument("--report", metavar="FILE", help="also write the markdown report to FILE")
        cmd.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")


def _problems_export(args: argparse.Namespace) -> int:
    from mpcform.bench.problems import DEFAULT_PROBLEMS_DIR, DEFAULT_SCENARIOS, export_problems

    out = Path(args.out) if args.out else DEFAULT_PROBLEMS_DIR
    paths = export_problems(args.scenarios or DEFAULT_SCENARIOS, out, args.per_scenario, args.solver)
    size = sum(p.stat().st_size for p in paths) / 2**20
    print(f"wrote {len(paths)} problems ({size:.1f} MiB) to {out}")
    return 0


def _add_problems(sub: argparse._SubParsersAction) -> None:
    from mpcform.bench.problems import DEFAULT_PER_SCENARIO

    problems = sub.add_parser("problems", help="recorded QP instances (problems/)")
    actions = problems.add_subparsers(dest="problems", required=True, metavar="ACTION")
    export = actions.add_parser("export", help="record the planner's QPs from scenarios into problems/")
    export.set_defaults(func=_problems_export)
    export.add_argument("scenarios", nargs="*", metavar="SCENARIO", help="scenarios (default: the swaps)")
    export.add_argument("--out", metavar="DIR", help="output directory (default: the bundled problems/)")
    export.add_argument("--per-scenario", type=int, default=DEFAULT_PER_SCENARIO, metavar="K",
                        help="QPs kept per scenario (a contiguous sequence)")  # fmt: skip
    export.add_argument("--solver", metavar="NAME", help="solver driving the runs (default: the scenario's)")


def _bench_scale(args: argparse.Namespace) -> int:
    from mpcform.bench import scale as bench_scale

    rows = bench_scale.run(args.n, args.scenario, args.coupling, args.steps, args.solver, args.horizon,
                           args.budget, args.monolithic_budget, isolate=not args.in_process,
                           trace_memory=args.tracemalloc, progress=_progress)  # fmt: skip
    text, growth = bench_scale.report(rows, args.coupling)
    _print_bench(text, rows + growth, args.json)
    return 0


def _add_bench_scale(kinds: argparse._SubParsersAction) -> None:
    from mpcform.bench.scale import DEFAULT_N
    from mpcform.bench.scale_cases import SCENARIOS
    from mpcform.mpc.settings import GROUPED_MODES

    scale = kinds.add_parser("scale", help="step time and peak memory, 10 to 1000 drones (growth exponent)")
    scale.set_defaults(func=_bench_scale)
    scale.add_argument("--n", type=int, nargs="+", default=list(DEFAULT_N), help="swarm sizes")
    scale.add_argument("--steps", type=int, default=30, help="closed-loop steps per case (dt 0.1 s)")
    scale.add_argument("--scenario", nargs="+", choices=SCENARIOS, default=list(SCENARIOS))
    scale.add_argument("--coupling", default="decoupled", choices=GROUPED_MODES,
                       help="planner mode, grouped (decoupled-sparse: one sparse QP, not per-drone DAQP)")
    scale.add_argument("--solver", default=DEFAULT_SOLVER, choices=PERSISTENT_SOLVERS, help="QP backend")
    scale.add_argument("--horizon", type=int, default=10, help="planner horizon [steps]")
    scale.add_argument("--budget", type=float, default=60.0, metavar="S",
                       help="planning time per case [s]; a case over it stops early")  # fmt: skip
    scale.add_argument("--monolithic-budget", type=float, default=60.0, metavar="S",
                       help="the same for the monolithic joint QP (0: skip it)")  # fmt: skip
    scale.add_argument("--tracemalloc", action="store_true", help="also trace Python/numpy allocations")
    scale.add_argument("--in-process", action="store_true", help="run the cases here, not in fresh processes")
    scale.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")


def _sweep(args: argparse.Namespace) -> int:
    from mpcform.run import sweep

    seeds = sweep.parse_seeds(args.seeds) if args.seeds else None
    sets = [sweep.parse_set(text) for text in args.set]
    jobs = sweep.build_jobs(args.scenario, seeds, sets, args.solver, args.tol)
    def progress(done: int, total: int) -> None:
        _progress(f"sweep: {done}/{total} runs")

    records = sweep.run_sweep(jobs, args.jobs, args.executor, args.scheduler, progress=progress)
    groups = sweep.aggregate(records)
    failed = sweep.failures_text(records)
    _print_bench(sweep.markdown_table(groups) + (f"\n\nfailed runs:\n{failed}" if failed else ""),
                 groups + records, args.json)  # fmt: skip
    return 0


def _add_sweep(sub: argparse._SubParsersAction) -> None:
    from mpcform.run.sweep import DEFAULT_TOLERANCE_M, EXECUTORS

    cmd = sub.add_parser("sweep", help="run a scenario over seeds and parameter values in parallel")
    cmd.set_defaults(func=_sweep)
    cmd.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
    cmd.add_argument("--seeds", metavar="SPEC", help="seeds, e.g. 0..19 or 0,3,7 (default: the file's)")
    cmd.add_argument("--set", action="append", default=[], metavar="KEY=V1,V2",
                     help="a dotted scenario key and its values, e.g. controller.horizon=5,10")  # fmt: skip
    cmd.add_argument("--jobs", type=int, default=1, metavar="N", help="worker processes")
    cmd.add_argument("--solver", metavar="NAME", help="override controller.solver (mpc)")
    cmd.add_argument("--tol", type=float, default=DEFAULT_TOLERANCE_M, metavar="M",
                     help="final tracking error of a successful run [m]")  # fmt: skip
    cmd.add_argument("--executor", default="process", choices=EXECUTORS, help="process pool or dask cluster")
    cmd.add_argument("--scheduler", metavar="ADDRESS", help="dask scheduler (default: a local cluster)")
    cmd.add_argument("--json", metavar="PATH", help="also write groups and runs as a JSON list of records")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``mpcform`` (each subcommand sets ``func``)."""
    parser = _Parser(prog="mpcform", description="Velocity planning for drone formations.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands: dict[str, tuple[str, Callable[[argparse.Namespace], int]]] = {
        "run": ("simulate a scenario and write trajectory.npz, trajectory.csv, summary.json", _run),
        "validate": ("check a scenario file", _validate),
        "solvers": ("list the QP backends: installed, usable for this QP, warm start, persistent", _solvers),
        "keys": ("print the reference of every scenario key (markdown)", _keys),
    }
    for name, (help_text, func) in commands.items():
        cmd = sub.add_parser(name, help=help_text, description=help_text)
        cmd.set_defaults(func=func)
        if name in ("run", "validate"):
            cmd.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
        if name == "run":
            cmd.add_argument("--out", metavar="DIR", help="output dir (default: results/<name>/)")
            cmd.add_argument("--controller", metavar="NAME", help="override controller.kind")
            cmd.add_argument("--solver", metavar="NAME", help="override controller.solver (mpc)")
            cmd.add_argument("--plant", metavar="KIND", choices=PLANT_KINDS,
                             help=f"override plant.kind: {', '.join(PLANT_KINDS)}")  # fmt: skip
            cli_runner.add_run_options(cmd)
    _add_bench(sub)
    _add_problems(sub)
    _add_sweep(sub)
    cli_runner.add_commands(sub)  # plot, compare, export
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        status: int = args.func(args)
        return status
    except (_UsageError, MPCFormError, OSError) as exc:  # OSError: e.g. an unwritable --out
        message = " ".join(str(exc).split())
        print(f"mpcform: error: {message}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
