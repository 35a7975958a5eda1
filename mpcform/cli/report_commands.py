"""The ``report`` subcommand of ``mpcform`` (wired in by :mod:`mpcform.cli.main`): regenerate the
measured tables of the repository's READMEs from real runs.

- ``scenarios/README.md``, between ``<!-- results:start -->`` and ``<!-- results:end -->``: one row
  per bundled scenario (``scenarios/*.toml``), each run as :func:`mpcform.run.runner.run_scenario`
  runs it (:func:`mpcform.outputs.report_tables.scenario_row`);
- ``problems/README.md``, between ``<!-- bench:start -->`` and ``<!-- bench:end -->``: the solver
  benchmark on the recorded problems (:mod:`mpcform.bench.solvers`, :mod:`mpcform.bench.report`)
  for a small solver set, and the planner's step against the bare solver on a small swap
  (:mod:`mpcform.bench.mpc`).

Each block opens with its provenance (commit, machine, UTC date). ``--check`` writes nothing: it
exits 1 with a one-line summary when a block's deterministic view (no timings, no provenance)
differs from the file's. Progress: one line per scenario or benchmark stage on stderr.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs import report_tables as rt

REPORT_HELP = "regenerate the measured tables of scenarios/README.md and problems/README.md"
REPORT_DESCRIPTION = (
    "Run every bundled scenario (scenarios/*.toml) and the solver benchmark on the recorded problems "
    "(problems/), and write their tables between the markers of scenarios/README.md "
    "(<!-- results:start/end -->) and problems/README.md (<!-- bench:start/end -->), each with the "
    "commit, machine and date that produced it; the text outside the markers is kept. --check "
    "writes nothing and exits 1 when the deterministic columns (all but timings) differ."
)
DEFAULT_SOLVERS = ("piqp", "osqp")
"""The benchmark's solvers, always installed; :data:`ACCURACY_SOLVER` joins them when usable."""
ACCURACY_SOLVER = "qpsolvers:clarabel"
MPC_CASE_N = 8  # drones of the planar swap of the planner-vs-solver table
MPC_SOLVER = "piqp"
DEFAULT_MPC_STEPS = 60
DEFAULT_SETTINGS = ("default",)
DEFAULT_TIME_LIMIT_S = 30.0
"""Per solve: generous, so that a loaded machine times out no solve (success is then deterministic)."""
EXIT_DIFFERS = 1
BENCH_DROPPED = ("- Machine:", "- Wall time of the benchmark:")
"""Lines of the solver report that describe the machine, not the code."""


@dataclass(frozen=True)
class Target:
    """One generated block: its file (relative to the root) and section, the titles of its timing
    columns and the prefixes of its machine lines (neither checked)."""

    path: str
    section: rt.Section
    timing: tuple[str, ...]
    drop: tuple[str, ...] = ()


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _git(root: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def provenance(root: Path) -> rt.Provenance:
    """The commit of ``root`` (``unknown`` outside git; dirty when a tracked file changed), this
    machine, the Python and numpy versions, today's UTC date."""
    commit = _git(root, "rev-parse", "--short", "HEAD")
    status = _git(root, "status", "--porcelain", "--untracked-files=no") if commit else None
    return rt.Provenance(
        commit=commit or "unknown",
        dirty=bool(status),
        machine=platform.processor() or platform.machine() or "unknown",
        cpus=os.cpu_count(),
        python=platform.python_version(),
        numpy=np.__version__,
        date=datetime.now(UTC).date().isoformat(),
    )


def scenario_table(root: Path, prov: rt.Provenance, say: Callable[[str], None] = _say) -> str:
    """Run every ``scenarios/*.toml`` under ``root``; the block of their rows."""
    from mpcform.run.runner import run_scenario
    from mpcform.scenario.load import load_scenario

    files = sorted((root / "scenarios").glob("*.toml"))
    if not files:
        raise ValidationError("--root", f"no scenario files (scenarios/*.toml) under {root}")
    rows = []
    for i, path in enumerate(files, 1):
        say(f"report: scenario {i}/{len(files)}: {path.name}")
        try:
            scenario = load_scenario(path)
            run = run_scenario(scenario)
        except (MPCFormError, ImportError) as exc:
            raise ValidationError(f"scenarios/{path.name}", " ".join(str(exc).split())) from None
        spec = scenario.controller
        coupling = spec.mpc.coupling if spec.kind == "mpc" else None
        rows.append(rt.scenario_row(path.name, run.summary, run.simulation.step_times_s, coupling))
    return rt.scenario_block(prov, rows)


def bench_solvers(requested: Sequence[str] | None) -> tuple[str, ...]:
    """The solvers to benchmark: ``requested``, else :data:`DEFAULT_SOLVERS` and
    :data:`ACCURACY_SOLVER` when it is usable; an unknown name is an error naming ``--solvers``."""
    from mpcform.solvers.registry import check_solver_name, solver_info

    names = list(requested) if requested else [*DEFAULT_SOLVERS]
    if not requested and solver_info(ACCURACY_SOLVER).usable:
        names.append(ACCURACY_SOLVER)
    for name in names:
        try:
            check_solver_name(name)
        except MPCFormError as exc:
            raise ValidationError("--solvers", str(exc)) from None
    return tuple(names)


def bench_timing() -> tuple[str, ...]:
    """The timing columns' titles of the solver report and the planner table (from their columns)."""
    from mpcform.bench import mpc as bench_mpc
    from mpcform.bench.report import SUMMARY_COLUMNS

    solver = [title for key, title, _ in SUMMARY_COLUMNS if key.endswith("_ms") or "ratio" in key]
    planner = [title for _, title, fmt in bench_mpc.COLUMNS if fmt != "{}"]
    return (*solver, *planner)


@dataclass(frozen=True)
class BenchOptions:
    """What the bench block runs: the solvers, their accuracy settings, the time limit per solve
    [s], and the planner-vs-solver swap's closed-loop steps."""

    solvers: tuple[str, ...]
    settings: tuple[str, ...] = DEFAULT_SETTINGS
    time_limit_s: float = DEFAULT_TIME_LIMIT_S
    mpc_steps: int = DEFAULT_MPC_STEPS


def bench_table(
    root: Path, prov: rt.Provenance, opts: BenchOptions, say: Callable[[str], None] = _say
) -> str:
    """The solver benchmark on ``root/problems`` and the planner-vs-solver table: the bench block."""
    from mpcform.bench import mpc as bench_mpc
    from mpcform.bench import report as bench_report
    from mpcform.bench import solvers as bs

    say(f"report: solver benchmark: {', '.join(opts.solvers)} on {root / 'problems'}")

    def progress(label: str, i: int, n: int) -> None:
        say(f"report: {i}/{n} {label}")

    bench = bs.run_solver_benchmark(
        root / "problems",
        opts.solvers,
        opts.settings,
        time_limit_s=opts.time_limit_s,
        exact=False,
        progress=progress,
    )
    steps = opts.mpc_steps
    say(f"report: planner vs bare solver: planar swap of {MPC_CASE_N}, {steps} steps")
    rows = bench_mpc.run([MPC_CASE_N], [], steps, MPC_SOLVER, "joint", 0.0, [], progress=progress)
    intro = (
        f"Solvers {', '.join(f'`{s}`' for s in opts.solvers)}, settings "
        f"{', '.join(f'`{s}`' for s in opts.settings)}, both modes, without the exact casadi:ipopt "
        f"reference (`mpcform report --solvers NAME ... --settings ...`; the full benchmark is "
        f"`mpcform bench solvers`). Timings vary by machine and load; `mpcform report --check` "
        "compares everything else."
    )
    planner = (
        f"`mpcform bench mpc` on a generated planar swap of {MPC_CASE_N} drones, {steps} steps, "
        f"{MPC_SOLVER}, joint coupling, without cvxpy: the planner's step against the same QPs on a bare "
        "persistent solver object."
    )
    return "\n\n".join(
        [
            prov.line(),
            intro,
            "### Solvers on the recorded problems",
            rt.demote_headings(bench_report.markdown_report(bench), levels=2),
            "### The planner's step against the bare solver",
            planner,
            bench_mpc.markdown_table(rows),
        ]
    )


SCENARIOS = Target("scenarios/README.md", rt.RESULTS, rt.SCENARIO_TIMING)


def _read(root: Path, target: Target) -> str:
    path = root / target.path
    try:
        text = path.read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValidationError(target.path, f"cannot read {path}: {exc}") from None
    rt.read_block(text, target.section, target.path)  # the markers, before any work
    return text


def _report(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    root = Path(args.root)
    if args.mpc_steps < 1:
        raise ValidationError("--mpc-steps", f"expected an integer >= 1, got {args.mpc_steps}")
    if not 0.0 < args.time_limit < float("inf"):
        raise ValidationError("--time-limit", f"expected a finite time > 0 [s], got {args.time_limit:g}")
    both = not (args.scenarios or args.problems)
    jobs: list[tuple[Target, Callable[[rt.Provenance], str]]] = []
    if args.scenarios or both:
        jobs.append((SCENARIOS, lambda prov: scenario_table(root, prov)))
    if args.problems or both:
        opts = BenchOptions(
            bench_solvers(args.solvers), tuple(args.settings), args.time_limit, args.mpc_steps
        )
        bench = Target("problems/README.md", rt.BENCH, bench_timing(), BENCH_DROPPED)
        jobs.append((bench, lambda prov: bench_table(root, prov, opts)))
    texts = [_read(root, target) for target, _ in jobs]  # every file and marker before any run
    prov = provenance(root)
    differ = []
    for (target, build), text in zip(jobs, texts, strict=True):
        block = build(prov)
        if args.check:
            old = rt.read_block(text, target.section, target.path)
            if (diff := rt.compare_blocks(target.path, old, block, target.timing, target.drop)) is not None:
                differ.append(diff)
        else:
            (root / target.path).write_bytes(
                rt.replace_block(text, target.section, block, target.path).encode()
            )
    took = time.perf_counter() - started
    names = ", ".join(t.path for t, _ in jobs)
    if differ:
        print(f"mpcform: report differs: {'; '.join(differ)}", file=sys.stderr)
        return EXIT_DIFFERS
    print(f"{'checked' if args.check else 'wrote'} {names} in {took:.0f} s")
    return 0


def add_report(sub: argparse._SubParsersAction) -> None:
    """``report``."""
    cmd = sub.add_parser("report", help=REPORT_HELP, description=REPORT_DESCRIPTION)
    cmd.set_defaults(func=_report)
    cmd.add_argument("--scenarios", action="store_true", help="the scenario table only")
    cmd.add_argument("--problems", action="store_true", help="the solver benchmark only")
    cmd.add_argument(
        "--check", action="store_true", help="write nothing; exit 1 when the deterministic columns differ"
    )
    cmd.add_argument("--root", default=".", metavar="DIR", help="the repository checkout (default: .)")
    cmd.add_argument(
        "--solvers",
        nargs="+",
        metavar="NAME",
        help=f"the benchmark's solvers (default: {', '.join(DEFAULT_SOLVERS)}, {ACCURACY_SOLVER} if usable)",
    )
    cmd.add_argument(
        "--settings",
        nargs="+",
        choices=("default", "low", "mid", "high"),
        default=list(DEFAULT_SETTINGS),
        help=f"the benchmark's accuracy settings (default: {' '.join(DEFAULT_SETTINGS)})",
    )
    cmd.add_argument(
        "--time-limit",
        type=float,
        default=DEFAULT_TIME_LIMIT_S,
        metavar="S",
        help=f"the benchmark's time limit per solve [s] (default {DEFAULT_TIME_LIMIT_S:g})",
    )
    cmd.add_argument(
        "--mpc-steps",
        type=int,
        default=DEFAULT_MPC_STEPS,
        metavar="N",
        help=f"closed-loop steps of the planner-vs-solver swap (default {DEFAULT_MPC_STEPS})",
    )
