"""The ``sweep`` subcommand of ``mpcform`` (wired in by :mod:`mpcform.cli.main`): one scenario over
seeds and parameter values, run by :mod:`mpcform.run.sweep`; ``--seeds`` and ``--set`` are parsed
here (an empty one is an error, and so is a sweep of more than ``mpcform.run.sweep.MAX_RUNS`` runs)."""

from __future__ import annotations

import argparse
import tomllib
from typing import Any

from mpcform.cli.options import add_max_memory, add_max_work, print_bench, progress, solver_help
from mpcform.errors import ValidationError

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

    seeds = parse_seeds(args.seeds) if args.seeds is not None else None  # '' is an error, not the file's
    sets = [parse_set(text) for text in args.set]
    jobs = sweep.build_jobs(args.scenario, seeds, sets, args.solver, args.tol)

    def report(done: int, total: int) -> None:
        progress(f"sweep: {done}/{total} runs")

    records = sweep.run_sweep(
        jobs,
        args.jobs,
        args.executor,
        args.scheduler,
        progress=report,
        max_memory_gib=args.max_memory,
        max_work=args.max_work,
    )
    groups = sweep.aggregate(records)
    failed = sweep.failures_text(records)
    print_bench(
        sweep.markdown_table(groups) + (f"\n\nfailed runs:\n{failed}" if failed else ""),
        groups + records,
        args.json,
    )
    return 0


def parse_seeds(text: str) -> list[int]:
    """``"0..19"`` (inclusive), ``"0,3,7"``, ``"5"``, or a mix (``"0..3,10"``)."""
    from mpcform.run.sweep import MAX_RUNS

    seeds: list[int] = []
    count = 0
    for part in text.split(","):
        part = part.strip()
        lo, sep, hi = part.partition("..")
        try:
            first, last = (int(lo), int(hi)) if sep else (int(part), int(part))
        except ValueError:
            raise ValidationError("--seeds", f"expected e.g. 0..19 or 0,3,7, got {text!r}") from None
        if first < 0 or last < first:
            raise ValidationError("--seeds", f"expected seeds >= 0 and ranges lo..hi, lo <= hi; got {part!r}")
        count += last - first + 1
        if count > MAX_RUNS:  # before the list is built (0..100000000 allocated gigabytes)
            raise ValidationError(
                "--seeds", f"{text!r} lists {count:,} seeds or more, above the limit of {MAX_RUNS:,} runs"
            )
        seeds.extend(range(first, last + 1))
    return list(dict.fromkeys(seeds))


def parse_set(text: str) -> tuple[str, list[Any]]:
    """``KEY=V1,V2,...``: a dotted key (``controller.horizon``; list items by index,
    ``obstacles.0.radius``) and its values, each a TOML value (``5``, ``0.1``, ``true``,
    ``[1.0, 2.0]``, ``"text"``) or a bare word taken as a string (``decoupled``)."""
    key, sep, values = text.partition("=")
    key = key.strip()
    parts = _split_top_level(values)
    if not sep or not key or any(not part for part in key.split(".")) or not all(p.strip() for p in parts):
        raise ValidationError("--set", f"expected KEY=VALUE[,VALUE...] without empty values, got {text!r}")
    return key, [parse_value(v) for v in parts]


def parse_value(text: str) -> Any:
    """A TOML value, or the stripped text itself when it is not one."""
    text = text.strip()
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _split_top_level(text: str) -> list[str]:
    """Split at commas outside brackets, braces and quotes."""
    parts, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return parts


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
    add_max_work(cmd, "run (each run of the sweep)")
