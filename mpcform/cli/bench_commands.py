"""The ``bench`` and ``problems`` subcommands of ``mpcform`` (wired in by :mod:`mpcform.cli.main`).

The benchmark modules are imported only when a benchmark runs (or its options are listed). A
benchmark checks its options, says its plan on stderr (:mod:`mpcform.cli.bench_plans`), then a
line per case (:class:`~mpcform.cli.progress.CaseLines`); stdout keeps the tables.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path

from mpcform.cli import bench_plans as plans
from mpcform.cli.options import DefaultsFormatter, add_profile, print_bench, seconds, solver_help
from mpcform.cli.progress import CaseLines
from mpcform.errors import ValidationError
from mpcform.scenario.load import load_scenario
from mpcform.scenario.size import DEFAULT_MAX_WORK
from mpcform.solvers.registry import DEFAULT_SOLVER, PERSISTENT_SOLVERS

PROBLEMS_OUT = "problems"  # problems export's default --out, relative to the working directory
DEFAULT_ONLINE_N = (20, 100, 1000)  # bench online's crossings
MAX_ONLINE_N = 5000  # the largest crossing bench online plans (as bench scale's largest case)
PLANT_DT_S = 0.1  # bench plant's control interval: its shortest flight


# ---- bench ----------------------------------------------------------------------------------
def _bench_mpc(args: argparse.Namespace) -> int:
    from mpcform.bench import mpc as bench_mpc  # benchmarks are imported only when asked for

    scenarios = bench_mpc.DEFAULT_SCENARIOS if args.scenarios is None else args.scenarios
    bench_mpc.check_cases(args.n, args.spatial_n, args.steps, scenarios, args.coupling)
    lines = _started("mpc", plans.mpc_plan(args, scenarios))
    rows = bench_mpc.run(
        args.n,
        args.spatial_n,
        args.steps,
        args.solver,
        args.coupling,
        args.cvxpy_budget,
        scenarios,
        progress=lines.case,
    )
    lines.done()
    print_bench(bench_mpc.markdown_table(rows), rows, args.json)
    return 0


def add_bench(sub: argparse._SubParsersAction) -> None:
    """``bench mpc``, ``bench solvers``, ``bench closed-loop``, ``bench scale``, ``bench split``,
    ``bench plant``."""
    bench = sub.add_parser("bench", help="benchmarks (markdown table; --json PATH for records)")
    kinds = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    mpc = kinds.add_parser("mpc", help="planner step times vs raw solver, numpy rollout and cvxpy")
    mpc.set_defaults(func=_bench_mpc)
    mpc.add_argument("--n", type=int, nargs="*", default=[8, 16, 32, 64], help="planar swap sizes")
    mpc.add_argument("--spatial-n", type=int, nargs="*", default=[20], help="spatial swap sizes")
    mpc.add_argument("--steps", type=int, default=60, help="closed-loop steps per generated swap (dt 0.1 s)")
    mpc.add_argument(
        "--scenarios",
        nargs="*",
        metavar="SCENARIO",
        help="scenario files run as they are (ideal plant; default: the bundled swaps "
        "swap_planar_8, swap_spatial_12, swap_spatial_20; none when given empty)",
    )
    mpc.add_argument(
        "--solver",
        default=DEFAULT_SOLVER,
        choices=PERSISTENT_SOLVERS,
        help="QP backend (decoupled, solved per drone: of the cvxpy reference only)",
    )
    mpc.add_argument(
        "--coupling",
        default="joint",
        choices=("joint", "decoupled", "decoupled-sparse"),
        help="planner mode (decoupled-sparse: one sparse QP, not per-drone DAQP QPs)",
    )
    mpc.add_argument(
        "--cvxpy-budget",
        type=seconds,
        default=60.0,
        metavar="S",
        help="cvxpy's time per case [s]: a case whose cvxpy time, extrapolated from its first "
        "QPs, exceeds it is skipped with the reason (default 60; 0: no cvxpy)",
    )
    mpc.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")
    _add_bench_solvers(kinds)
    _add_bench_scale(kinds)
    split = kinds.add_parser("split", help="iterated split points: QP cost gap to the joint vs rounds, time")
    split.set_defaults(func=_bench_split)
    split.add_argument(
        "--scenarios",
        nargs="+",
        metavar="SCENARIO",
        help="scenario files, flown decoupled (default: swap_planar_8, swap_spatial_12, swap_spatial_20)",
    )
    split.add_argument(
        "--rounds",
        type=int,
        nargs="+",
        default=[0, 1, 2, 5, 10, 20, 50],
        help="split rounds per step (the table's rows; the planner flies with the most)",
    )
    split.add_argument("--steps", type=int, help="closed-loop steps per scenario (default: its duration)")
    split.add_argument("--figure", metavar="PNG", help="write the convergence curves to this PNG")
    split.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")
    plant = kinds.add_parser("plant", help="the quadrotor plant alone: n drones, a fixed command sequence")
    plant.set_defaults(func=_bench_plant)
    plant.add_argument("--n", type=int, default=20, help="drones")
    plant.add_argument("--duration", type=float, default=12.0, help="flight time [s]")
    plant.add_argument("--rate", type=float, default=500.0, help="inner-loop rate [Hz]")
    plant.add_argument("--repeats", type=int, default=3, help="runs (median and max are reported)")
    plant.add_argument("--no-wind", action="store_true", help="still air (default: gusts of 0.5 m/s)")
    plant.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")
    online = kinds.add_parser(
        "online", help="the online loop: step times and deadline fallbacks in a crossing"
    )
    online.set_defaults(func=_bench_online)
    online.add_argument("--n", type=int, nargs="+", default=list(DEFAULT_ONLINE_N), help="drones per case")
    online.add_argument("--steps", type=int, default=60, help="periods of 0.1 s per case")
    online.add_argument("--budget", type=float, default=0.1, help="the step deadline [s]")
    online.add_argument("--coupling", choices=("decoupled", "joint"), default="decoupled", help="the rows")
    online.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")
    add_profile(online)
    for choice in kinds._choices_actions:  # each benchmark's --help: what it measures, the defaults' time
        parser = kinds.choices[choice.dest]
        parser.description = f"{choice.help}. {plans.run_time_help(choice.dest)}"
        parser.formatter_class = DefaultsFormatter


def _started(name: str, plan: str) -> CaseLines:
    """The progress lines of ``bench NAME``, its plan said first."""
    lines = CaseLines(f"bench {name}")
    lines.say(plan)
    return lines


def _bench_split(args: argparse.Namespace) -> int:
    from mpcform.bench import split as bench_split

    if min(args.rounds) < 0 or (args.steps is not None and args.steps < 1):
        print("mpcform: error: --rounds must be >= 0 and --steps >= 1", file=sys.stderr)
        return 2
    scenarios = bench_split.DEFAULT_SCENARIOS if args.scenarios is None else tuple(args.scenarios)
    for path in scenarios:  # an unreadable or invalid file is one error line, before the plan
        load_scenario(path)
    lines = _started("split", plans.split_plan(args, scenarios))
    rows = bench_split.run(scenarios, tuple(args.rounds), args.steps, args.figure, progress=lines.case)
    lines.done()
    print_bench(bench_split.markdown_table(rows), rows, args.json)
    return 0


def _bench_plant(args: argparse.Namespace) -> int:
    from mpcform.bench import plant as bench_plant

    check_plant_options(args)
    lines = _started("plant", plans.plant_plan(args))
    rows = bench_plant.run(
        args.n, args.duration, args.rate, args.repeats, wind=not args.no_wind, progress=lines.case
    )
    lines.done()
    print_bench(bench_plant.markdown_table(rows), rows, args.json)
    return 0


def _bench_online(args: argparse.Namespace) -> int:
    from mpcform.bench import online as bench_online
    from mpcform.online.loop import JOINT_ONLINE_MAX_DRONES

    if min(args.n) < 2 or max(args.n) > MAX_ONLINE_N or args.steps < 1:
        flag, value = ("--steps", args.steps) if args.steps < 1 else ("--n", args.n)
        raise ValidationError(flag, f"expected --n in 2..{MAX_ONLINE_N} and --steps >= 1, got {value}")
    if not 0.0 < args.budget < math.inf:
        raise ValidationError("--budget", f"expected a finite deadline > 0 [s], got {args.budget:g}")
    if args.coupling == "joint" and max(args.n) > JOINT_ONLINE_MAX_DRONES:
        raise ValidationError(
            "--coupling",
            f"joint is planned online for at most {JOINT_ONLINE_MAX_DRONES} drones, got --n {args.n}",
        )
    lines = _started("online", plans.online_plan(args))
    rows = bench_online.run(
        tuple(args.n), args.steps, args.budget, args.coupling, progress=lines.case, profile_path=args.profile
    )
    lines.done()
    print_bench(bench_online.markdown_table(rows), [*rows, bench_online.growth(rows)], args.json)
    return 0


def check_plant_options(args: argparse.Namespace) -> None:
    """``bench plant``'s sizes, before anything is allocated: one error naming the option (its
    inner steps x drones within the run's default ``--max-work``)."""
    if args.n < 1 or args.repeats < 1:
        flag, value = ("--n", args.n) if args.n < 1 else ("--repeats", args.repeats)
        raise ValidationError(flag, f"expected an integer >= 1, got {value}")
    if not PLANT_DT_S <= args.duration < math.inf:
        what = f"a flight time >= {PLANT_DT_S:g} s (one control interval)"
        raise ValidationError("--duration", f"expected {what}, got {args.duration:g}")
    if not 0.0 < args.rate < math.inf:
        raise ValidationError("--rate", f"expected a finite inner-loop rate > 0 [Hz], got {args.rate:g}")
    work = args.rate * args.duration * args.n
    if work > DEFAULT_MAX_WORK:
        ratios = {"--duration": args.duration / 12.0, "--rate": args.rate / 500.0, "--n": args.n / 20.0}
        raise ValidationError(
            max(ratios, key=lambda k: ratios[k]),
            f"the plant would take {work:.3g} inner steps x drones ({args.rate:g} Hz x {args.duration:g} s x "
            f"{args.n:,} drones), above the limit of {DEFAULT_MAX_WORK:.3g}: lower --duration, --rate or --n",
        )


def _bench_solvers(args: argparse.Namespace) -> int:
    from mpcform.bench import report as bench_report
    from mpcform.bench import solvers as bs
    from mpcform.bench.accuracy import default_solvers
    from mpcform.bench.problems import problem_files

    problems = args.problems or bs.DEFAULT_PROBLEMS_DIR
    lines = _started("solvers", plans.solvers_plan(args, len(problem_files(problems)), str(problems)))
    names = _solver_names(lines, args.solvers, default_solvers)
    bench = bs.run_solver_benchmark(
        problems,
        names,
        args.settings,
        args.modes,
        args.time_limit,
        exact=not args.no_exact,
        progress=lines.case,
    )
    lines.done()
    report = bench_report.markdown_report(bench)
    print_bench(report, bench_report.records(bench), args.json)
    if args.report:
        Path(args.report).write_text(report + "\n")
    return 0


def _bench_closed_loop(args: argparse.Namespace) -> int:
    from mpcform.bench import closed_loop
    from mpcform.bench.accuracy import default_solvers
    from mpcform.bench.problems import DEFAULT_SCENARIOS

    scenarios = args.scenarios or DEFAULT_SCENARIOS[:2]
    for scenario in scenarios:  # an invalid one is one error line, before the plan
        closed_loop.load_bench_scenario(scenario, args.duration, DEFAULT_SOLVER)
    lines = _started("closed-loop", plans.closed_loop_plan(args, scenarios))
    names = _solver_names(lines, args.solvers, default_solvers)
    rows = closed_loop.run_closed_loop(scenarios, names, args.timeout, args.duration, progress=lines.case)
    lines.done()
    report = closed_loop.closed_loop_markdown(rows)
    print_bench(report, rows, args.json)
    if args.report:
        Path(args.report).write_text(report)
    return 0


def _solver_names(lines: CaseLines, names: list[str] | None, known: Callable[[], list[str]]) -> list[str]:
    """The solvers asked for, or every known one (looked up after the plan: it imports them)."""
    if names:
        return names
    names = known()
    lines.say(f"solvers: {', '.join(names)} (a missing or unsupported one is reported, not run)")
    return names


def _add_bench_solvers(kinds: argparse._SubParsersAction) -> None:
    from mpcform.bench.accuracy import SETTINGS
    from mpcform.bench.solvers import DEFAULT_TIME_LIMIT_S
    from mpcform.bench.worker import MODES

    solvers = kinds.add_parser("solvers", help="QP solvers on the recorded problems (problems/)")
    solvers.set_defaults(func=_bench_solvers)
    solvers.add_argument("--problems", metavar="DIR", help="problem directory (default: bundled problems/)")
    solvers.add_argument(
        "--solvers", nargs="+", metavar="NAME", help=solver_help("backends (default: all known)")
    )
    solvers.add_argument("--settings", nargs="+", choices=list(SETTINGS), default=list(SETTINGS))
    solvers.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    solvers.add_argument(
        "--time-limit", type=float, default=DEFAULT_TIME_LIMIT_S, metavar="S", help="per-solve time limit [s]"
    )
    solvers.add_argument("--no-exact", action="store_true", help="skip the casadi:ipopt exact reference")
    loop = kinds.add_parser("closed-loop", help="each solver drives the same scenarios through the planner")
    loop.set_defaults(func=_bench_closed_loop)
    loop.add_argument("scenarios", nargs="*", metavar="SCENARIO", help="scenario files (default: the swaps)")
    loop.add_argument(
        "--solvers", nargs="+", metavar="NAME", help=solver_help("backends (default: all usable)")
    )
    loop.add_argument("--timeout", type=float, default=600.0, metavar="S", help="time limit per run [s]")
    loop.add_argument("--duration", type=float, metavar="S", help="override the scenarios' duration [s]")
    for cmd in (solvers, loop):
        cmd.add_argument("--report", metavar="FILE", help="also write the markdown report to FILE")
        cmd.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")


def _bench_scale(args: argparse.Namespace) -> int:
    from mpcform.bench import scale as bench_scale
    from mpcform.bench.scale_report import report

    bench_scale.check_options(
        args.n, args.scenario, args.coupling, args.steps, args.solver, args.horizon, args.monolithic_budget
    )
    lines = _started("scale", plans.scale_plan(args))
    rows = bench_scale.run(
        args.n,
        args.scenario,
        args.coupling,
        args.steps,
        args.solver,
        args.horizon,
        args.budget,
        args.monolithic_budget,
        isolate=not args.in_process,
        trace_memory=args.tracemalloc,
        progress=lines.case,
        profile_path=args.profile,
    )
    lines.done()
    text, growth = report(rows, args.coupling)
    print_bench(text, rows + growth, args.json)
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
    scale.add_argument(
        "--coupling",
        default="decoupled",
        choices=GROUPED_MODES,
        help="planner mode, grouped (decoupled-sparse: one sparse QP, not per-drone DAQP)",
    )
    scale.add_argument("--solver", default=DEFAULT_SOLVER, choices=PERSISTENT_SOLVERS, help="QP backend")
    scale.add_argument("--horizon", type=int, default=10, help="planner horizon [steps]")
    scale.add_argument(
        "--budget",
        type=float,
        default=60.0,
        metavar="S",
        help="planning time per case [s]; a case over it stops early",
    )
    scale.add_argument(
        "--monolithic-budget",
        type=float,
        default=60.0,
        metavar="S",
        help="the same for the monolithic joint QP (0: skip it)",
    )
    scale.add_argument("--tracemalloc", action="store_true", help="also trace Python/numpy allocations")
    scale.add_argument("--in-process", action="store_true", help="run the cases here, not in fresh processes")
    scale.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")
    add_profile(scale)


# ---- problems -------------------------------------------------------------------------------
def _problems_export(args: argparse.Namespace) -> int:
    from mpcform.bench.problems import DEFAULT_SCENARIOS, export_problems

    out = Path(args.out) if args.out else Path(PROBLEMS_OUT)  # not into the installed package
    paths = export_problems(args.scenarios or DEFAULT_SCENARIOS, out, args.per_scenario, args.solver)
    size = sum(p.stat().st_size for p in paths) / 2**20
    print(f"wrote {len(paths)} problems ({size:.1f} MiB) to {out}")
    return 0


def add_problems(sub: argparse._SubParsersAction) -> None:
    """``problems export``."""
    from mpcform.bench.problems import DEFAULT_PER_SCENARIO

    problems = sub.add_parser("problems", help="recorded QP instances (problems/)")
    actions = problems.add_subparsers(dest="problems", required=True, metavar="ACTION")
    export = actions.add_parser("export", help="record the planner's QPs from scenarios into ./problems/")
    export.set_defaults(func=_problems_export)
    export.add_argument("scenarios", nargs="*", metavar="SCENARIO", help="scenarios (default: the swaps)")
    export.add_argument(
        "--out",
        metavar="DIR",
        help=f"output directory (default: ./{PROBLEMS_OUT}/, the bundled one in a checkout)",
    )
    export.add_argument(
        "--per-scenario",
        type=int,
        default=DEFAULT_PER_SCENARIO,
        metavar="K",
        help="QPs kept per scenario (a contiguous sequence)",
    )
    export.add_argument(
        "--solver", metavar="NAME", help=solver_help("solver driving the runs (default: the scenario's)")
    )
