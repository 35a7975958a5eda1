"""What the subcommands' wiring shares: option types (``--max-memory``, ``--max-work``, a time
budget, a benchmark's ``--profile``), the solvers' help text, and how the table commands print
(markdown on stdout, ``--json`` records, progress lines on a terminal's stderr)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from mpcform.errors import ValidationError
from mpcform.scenario.size import DEFAULT_MAX_MEMORY_GIB, DEFAULT_MAX_WORK
from mpcform.solvers.registry import DEFAULT_SOLVER, PERSISTENT_SOLVERS


def solver_help(what: str = "QP backend") -> str:
    """Help text naming the solvers: the registry's backends and the two families."""
    from mpcform.solvers.casadi_conic import CASADI_CONIC_PLUGINS

    named = ", ".join(f"{b} (default)" if b == DEFAULT_SOLVER else b for b in PERSISTENT_SOLVERS)
    return (
        f"{what}: {named}, qpsolvers:<name>, casadi:<plugin> ({', '.join(CASADI_CONIC_PLUGINS)}) "
        "or casadi:ipopt; `mpcform solvers` shows which are installed"
    )


class DefaultsFormatter(argparse.HelpFormatter):
    """Help that ends each option with its default, unless it has none (None, False) or says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (
            action.default in (None, False, argparse.SUPPRESS)
            or "default" in text
            or not action.option_strings
        ):
            return text
        return f"{text} (default: %(default)s)"


def _finite(text: str, what: str, zero: bool = False) -> float:
    """``text`` as a finite number > 0 (``zero``: >= 0), else an argparse error naming ``what``."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (0 <= value if zero else 0 < value) or value == float("inf"):
        raise argparse.ArgumentTypeError(
            f"expected a number of {what} {'>=' if zero else '>'} 0, got {text!r}"
        )
    return value


def max_memory_gib(text: str) -> float:
    """The ``--max-memory`` value: a number of GiB > 0."""
    return _finite(text, "GiB")


def max_work(text: str) -> float:
    """The ``--max-work`` value: a number of plant inner steps x drones > 0."""
    return _finite(text, "inner steps x drones")


def seconds(text: str) -> float:
    """A time budget [s]: a finite number >= 0."""
    return _finite(text, "seconds", zero=True)


def add_max_memory(cmd: argparse.ArgumentParser, per: str = "run") -> None:
    """The ``--max-memory GIB`` option (see :mod:`mpcform.scenario.size`)."""
    cmd.add_argument(
        "--max-memory",
        type=max_memory_gib,
        default=DEFAULT_MAX_MEMORY_GIB,
        metavar="GIB",
        help=f"refuse a {per} estimated to need more memory than this [GiB] "
        f"(default {DEFAULT_MAX_MEMORY_GIB:g})",
    )


def add_max_work(cmd: argparse.ArgumentParser, per: str = "run") -> None:
    """The ``--max-work N`` option (see :func:`mpcform.scenario.size.check_work`)."""
    cmd.add_argument(
        "--max-work",
        type=max_work,
        default=DEFAULT_MAX_WORK,
        metavar="N",
        help=f"refuse a {per} whose plant takes more inner steps x drones than this (the "
        f"quadrotor's rate x duration x n; default {DEFAULT_MAX_WORK:g}), or whose MPC's sparse QP "
        "nonzeros x steps exceed twice it",
    )


def add_profile(cmd: argparse.ArgumentParser) -> None:
    """``--profile PATH`` of a benchmark (checked before any case, with the other output files:
    :mod:`mpcform.cli.paths`)."""
    cmd.add_argument(
        "--profile",
        metavar="PATH",
        help="also run each case a second time, untimed, under cProfile, and write the top 30 functions "
        "by tottime of its planner steps to PATH (a header line per case)",
    )


@contextmanager
def option_errors(*fields: str) -> Iterator[None]:
    """Re-raise a :class:`ValidationError` of one of the library's ``fields`` (``max_speed``)
    naming the option the user wrote (``--max-speed``)."""
    try:
        yield
    except ValidationError as exc:
        if exc.field not in fields:
            raise
        raise ValidationError("--" + exc.field.replace("_", "-"), exc.message) from None


def print_bench(table: str, rows: list[dict[str, Any]], json_path: str | None) -> None:
    """Print a benchmark's markdown and write its records to ``json_path`` (if given)."""
    print(table)
    if json_path:
        Path(json_path).write_text(json.dumps(rows, indent=2, default=float) + "\n")


def progress(text: str) -> None:
    """A progress line on stderr, when it is a terminal."""
    if sys.stderr.isatty():
        print(text, file=sys.stderr, flush=True)
