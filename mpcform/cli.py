"""The ``mpcform`` command: a thin argparse layer over :mod:`mpcform.scenario`.

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

from mpcform.errors import MPCFormError
from mpcform.mpc_settings import COUPLINGS
from mpcform.output import OUTPUT_FILES, format_summary
from mpcform.scenario import (
    build_controller,
    describe,
    key_reference_markdown,
    load_scenario,
    run_scenario,
    solver_backends,
)
from mpcform.solvers import BACKENDS, DEFAULT_SOLVER

EXIT_USAGE = 2


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        raise _UsageError(message)


def _run(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    out_dir = Path("results") / scenario.name if args.out is None else Path(args.out)
    run = run_scenario(scenario, out_dir, controller=args.controller, solver=args.solver)
    print(format_summary(run.summary))
    print(f"wrote {', '.join(OUTPUT_FILES)} to {run.out_dir}")
    return 0


def _validate(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    build_controller(scenario)  # e.g. the mpc controller needs limits.v_max with d_min
    print(f"OK {describe(scenario)}")
    return 0


def _solvers(args: argparse.Namespace) -> int:
    rows = solver_backends()
    width = max(len(name) for name, _ in rows)
    print(f"{'solver':<{width}}  installed")
    for name, ok in rows:
        print(f"{name:<{width}}  {'yes' if ok else 'no'}")
    return 0


def _keys(args: argparse.Namespace) -> int:
    print(key_reference_markdown(), end="")
    return 0


def _bench_mpc(args: argparse.Namespace) -> int:
    from mpcform import bench_mpc  # benchmarks are imported only when asked for

    rows = bench_mpc.run(args.n, args.spatial_n, args.steps, args.solver, args.coupling, args.cvxpy_max_n)
    _print_bench(bench_mpc.markdown_table(rows), rows, args.json)
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
    mpc.add_argument("--solver", default=DEFAULT_SOLVER, choices=sorted(BACKENDS), help="QP backend")
    mpc.add_argument("--coupling", default="joint", choices=COUPLINGS)
    mpc.add_argument("--cvxpy-max-n", type=int, default=16, help="largest n also run through cvxpy")
    mpc.add_argument("--json", metavar="PATH", help="also write the rows as a JSON list of records")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``mpcform`` (each subcommand sets ``func``)."""
    parser = _Parser(prog="mpcform", description="Velocity planning for drone formations.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands: dict[str, tuple[str, Callable[[argparse.Namespace], int]]] = {
        "run": ("simulate a scenario and write trajectory.npz, trajectory.csv, summary.json", _run),
        "validate": ("check a scenario file", _validate),
        "solvers": ("list the QP backends and whether they are installed", _solvers),
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
    _add_bench(sub)
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
