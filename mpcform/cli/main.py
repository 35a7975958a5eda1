"""The ``mpcform`` command: a thin argparse layer over :mod:`mpcform.run.runner`.

Errors in user input print one line ``mpcform: error: <message>`` on stderr and exit with
status 2 (argparse usage errors too); no traceback. A problem of a scenario file reads
``mpcform: error: FILE:LINE: KEY: MESSAGE`` (``FILE: KEY: MESSAGE`` when the key has no line in
the file, ``FILE: MESSAGE`` when the file cannot be read or parsed); ``validate`` prints one such
line per problem, then ``mpcform: N problems in FILE`` when there are several. Output paths are
checked before any work. When stdout is a pipe closed early (``mpcform keys | head -1``) the
command stops quietly with status 141, as a program killed by SIGPIPE (128 + 13).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable
from dataclasses import replace
from importlib import metadata
from pathlib import Path
from typing import NoReturn

from mpcform.cli import bench_commands, report_commands, sweep_commands
from mpcform.cli import handlers as cli_runner
from mpcform.cli.options import add_max_memory, add_max_work, solver_help
from mpcform.cli.paths import check_output_dir, check_output_paths
from mpcform.cli.signals import Terminated, terminating
from mpcform.errors import MPCFormError, ScenarioError, ValidationError
from mpcform.outputs.files import (
    OUTPUT_FILES,
    format_summary,
    incomplete_warning,
    plant_events,
    write_outputs,
)
from mpcform.outputs.outdir import RUN_LAYOUT, claim_dir
from mpcform.run.heap import keep_heap
from mpcform.run.runner import RunResult, describe, run_scenario
from mpcform.scenario.build import check_solver_key
from mpcform.scenario.check import check_scenario_file, located_problem
from mpcform.scenario.keys import key_reference_markdown
from mpcform.scenario.load import load_scenario
from mpcform.scenario.plant import with_plant_kind
from mpcform.scenario.schema import CONTROLLER_KINDS, did_you_mean, listing
from mpcform.scenario.size import check_memory, check_work
from mpcform.scenario.spec import Scenario
from mpcform.sim.plants import KINDS as PLANT_KINDS
from mpcform.solvers.registry import solver_info, solver_infos
from mpcform.world.limits import PLATFORM_TRACKING_M

EXIT_USAGE = 2
EXIT_INTERRUPTED = 128 + 2  # what a shell reports for a program stopped by SIGINT (Ctrl-C)
EXIT_BROKEN_PIPE = 128 + 13  # what a shell reports for a program killed by SIGPIPE


class _UsageError(Exception):
    pass


RUN_OUTPUTS = tuple(RUN_LAYOUT)
"""What ``run`` writes into its ``--out`` directory (an earlier run's, by its manifest, removed first)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, as every other error (no usage block)
        raise _UsageError(f"{message} (see `{self.prog} --help`)")


def _run(args: argparse.Namespace) -> int:
    try:
        scenario = load_scenario(args.scenario, max_memory_gib=args.max_memory)
        if args.plant is not None:
            scenario = with_plant_kind(scenario, args.plant)
        if args.flyable:
            scenario = scenario.flyable()
        _check_overrides(args)
        check_memory(scenario, args.max_memory, args.controller)  # before anything large is allocated
        check_work(scenario, args.max_work, args.controller)
        cli_runner.check_run_options(args, scenario)  # e.g. --plot without matplotlib: fail before running
        out_dir = Path("results") / scenario.name if args.out is None else Path(args.out)
        check_output_dir("--out", out_dir)
        with claim_dir(out_dir, "run", RUN_OUTPUTS, field="--out") as claim:  # refused before the run
            for warning in scenario.warnings(args.controller):
                print(f"mpcform: warning: {warning}", file=sys.stderr)
            run = run_scenario(
                scenario,
                controller=args.controller,
                solver=args.solver,
                progress=cli_runner.progress_bar(scenario),
            )
            if removed := claim.clear():  # the earlier run's outputs stay until this one is done
                print(f"mpcform: {out_dir}: replaced the earlier run's {', '.join(removed)}", file=sys.stderr)
            run = replace(run, out_dir=write_outputs(out_dir, run.simulation, run.summary))
            _report_run(args, scenario, run)
    except ScenarioError as exc:
        raise MPCFormError(located_problem(exc, args.scenario).text(args.scenario)) from None
    return 0


def _report_run(args: argparse.Namespace, scenario: Scenario, run: RunResult) -> None:
    print(format_summary(run.summary))
    if (incomplete := incomplete_warning(run.summary)) is not None:
        print(f"mpcform: warning: {incomplete}", file=sys.stderr)
    if (events := plant_events(run.summary.get("plant") or {})) is not None:
        print(f"mpcform: warning: the plant reports {events}", file=sys.stderr)
    print(f"wrote {', '.join(OUTPUT_FILES)} to {run.out_dir}")
    cli_runner.finish_run(args, scenario, run)  # --plot, --animate, --export


def _check_overrides(args: argparse.Namespace) -> None:
    """``--controller`` and ``--solver`` name a controller kind and a solver (errors name the flag)."""
    if args.controller is not None and args.controller not in CONTROLLER_KINDS:
        hint = did_you_mean(args.controller, CONTROLLER_KINDS)
        raise ValidationError(
            "--controller", f"expected one of {listing(CONTROLLER_KINDS)}, got {args.controller!r}{hint}"
        )
    if args.solver is not None:
        try:
            check_solver_key(args.solver, "--solver")
        except ScenarioError as exc:
            raise ValidationError("--solver", str(exc).removeprefix("--solver: ")) from None
        info = solver_info(args.solver)
        if not info.usable:  # not installed, or cannot take this QP: before the run, naming the flag
            raise ValidationError("--solver", f"{args.solver!r}: {info.note}")


def _validate(args: argparse.Namespace) -> int:
    result = check_scenario_file(args.scenario, args.max_memory, max_work=args.max_work)
    if result.scenario is not None:
        print(f"OK {describe(result.scenario)}")
        for warning in result.scenario.warnings():
            print(f"mpcform: warning: {args.scenario}: {warning}", file=sys.stderr)
        return 0
    for problem in result.problems:
        print(f"mpcform: error: {problem.text(args.scenario)}", file=sys.stderr)
    if len(result.problems) > 1:
        print(f"mpcform: {len(result.problems)} problems in {args.scenario}", file=sys.stderr)
    return EXIT_USAGE


def _solvers(args: argparse.Namespace) -> int:
    rows = solver_infos(per_drone=args.per_drone)
    width = max(len(r.name) for r in rows)
    print(f"{'solver':<{width}}  installed  usable  warm  persistent  note")
    for r in rows:
        flags = (r.installed, r.usable, r.warm_start, r.persistent)
        yes = [f"{'yes' if f else 'no':<{w}}" for f, w in zip(flags, (9, 6, 4, 10), strict=True)]
        print(f"{r.name:<{width}}  {'  '.join(yes)}  {r.note}")
    return 0


def _keys(args: argparse.Namespace) -> int:
    if args.json_schema:
        from mpcform.scenario.json_schema import scenario_json_schema

        print(json.dumps(scenario_json_schema(), indent=2))
    else:
        print(key_reference_markdown(), end="")
    return 0


def _version() -> str:
    try:
        return metadata.version("mpcform")
    except metadata.PackageNotFoundError:
        return "0+unknown"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``mpcform`` (each subcommand sets ``func``)."""
    parser = _Parser(prog="mpcform", description="Velocity planning for drone formations.")
    parser.add_argument("--version", action="version", version=f"mpcform {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands: dict[str, tuple[str, Callable[[argparse.Namespace], int]]] = {
        "run": ("simulate a scenario and write trajectory.npz, trajectory.csv, summary.json", _run),
        "validate": ("check a scenario file: every problem, with its line", _validate),
        "solvers": ("list the QP backends: installed, usable for this QP, warm start, persistent", _solvers),
        "keys": ("print the reference of every scenario key (markdown)", _keys),
    }
    for name, (help_text, func) in commands.items():
        cmd = sub.add_parser(name, help=help_text, description=help_text)
        cmd.set_defaults(func=func)
        if name in ("run", "validate"):
            cmd.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
            add_max_memory(cmd)
            add_max_work(cmd)
        if name == "run":
            cmd.add_argument("--out", metavar="DIR", help="output dir (default: results/<name>/)")
            cmd.add_argument(
                "--controller",
                metavar="NAME",
                help=f"override controller.kind: {', '.join(CONTROLLER_KINDS)}",
            )
            cmd.add_argument(
                "--solver",
                metavar="NAME",
                help=solver_help("override the sparse backend of [controller.solve] (mpc)"),
            )
            cmd.add_argument(
                "--plant",
                metavar="KIND",
                choices=PLANT_KINDS,
                help=f"override plant.kind: {', '.join(PLANT_KINDS)}",
            )
            cmd.add_argument(
                "--flyable",
                action="store_true",
                help="plan for a Crazyflie: keep its tracking allowance (limits.tracking, else "
                f"{PLATFORM_TRACKING_M:g} m per drone), which export requires",
            )
            cli_runner.add_run_options(cmd)
        if name == "solvers":
            cmd.add_argument(
                "--per-drone",
                action="store_true",
                help='the per-drone backends instead ([controller.solve] kind = "per_drone")',
            )
        if name == "keys":
            cmd.add_argument(
                "--json-schema",
                action="store_true",
                help="print the scenario format as a JSON Schema (draft 2020-12)",
            )
    bench_commands.add_bench(sub)
    bench_commands.add_problems(sub)
    sweep_commands.add_sweep(sub)
    report_commands.add_report(sub)
    cli_runner.add_commands(sub)  # plot, compare, export
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    keep_heap()  # large runs: freed arrays stay in the heap (see mpcform.run.heap)
    parser = build_parser()
    try:
        with terminating():  # SIGTERM, SIGHUP: as Ctrl-C
            args = parser.parse_args(argv)
            check_output_paths(args)  # --out, --json, --report, --figure: before any work
            status: int = args.func(args)
            sys.stdout.flush()  # a reader that closed the pipe shows here, not at exit
            return status
    except BrokenPipeError:
        _discard_stdout()
        return EXIT_BROKEN_PIPE
    except Terminated as exc:  # one line, the shell's status for the signal
        print(f"mpcform: interrupted ({exc.name})", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:  # Ctrl-C: one line, the shell's status for SIGINT
        print("mpcform: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (_UsageError, MPCFormError, OSError) as exc:  # OSError: e.g. an unwritable --out
        message = " ".join(str(exc).split())
        print(f"mpcform: error: {message}", file=sys.stderr)
        return EXIT_USAGE


def _discard_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's final flush does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no file descriptor (e.g. a captured stream)
        pass


if __name__ == "__main__":
    sys.exit(main())
