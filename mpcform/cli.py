"""The ``mpcform`` command: a thin argparse layer over :mod:`mpcform.scenario`.

Errors in user input print one line ``mpcform: error: <message>`` on stderr and exit with
status 2 (argparse usage errors too); no traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from mpcform.errors import MPCFormError
from mpcform.output import OUTPUT_FILES, format_summary
from mpcform.scenario import (
    build_controller,
    describe,
    key_reference_markdown,
    load_scenario,
    run_scenario,
    solver_backends,
)

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
