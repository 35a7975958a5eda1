"""The markdown report and JSON records of ``mpcform bench solvers``."""

from __future__ import annotations

import os
import platform
from collections.abc import Sequence
from importlib import metadata
from typing import Any

import numpy as np

from mpcform.bench.accuracy import EXACT_SOLVER, REFERENCE_EPS, REFERENCE_SOLVER, TOLERANCES, objective_gap
from mpcform.bench.problems import RecordedQP
from mpcform.bench.solvers import EXACT_TIME_LIMIT_S, SolverBenchmark
from mpcform.bench.stats import SHIFT_S
from mpcform.outputs.tables import Column, markdown_table

SOLVER_PACKAGES = (
    "osqp",
    "piqp",
    "qpsolvers",
    "clarabel",
    "daqp",
    "highspy",
    "proxsuite",
    "quadprog",
    "scs",
    "casadi",
)
"""The packages whose installed versions the report lists."""
SUMMARY_COLUMNS: list[Column] = [
    ("solver", "solver", "{}"),
    ("success_rate", "success [%]", "{:.0f}"),
    ("shgeom_runtime_ms", "shgeom [ms]", "{:.3g}"),
    ("shgeom_ratio", "ratio", "{:.1f}"),
    ("median_runtime_ms", "median [ms]", "{:.3g}"),
    ("p90_runtime_ms", "p90 [ms]", "{:.3g}"),
    ("primal_residual_max", "max primal residual", "{:.1e}"),
    ("objective_gap_max", "max objective gap", "{:.1e}"),
    ("failures", "failures", "{}"),
]
EXACT_COLUMNS: list[Column] = [
    ("scenario", "scenario", "{}"),
    ("solved", "solved", "{}"),
    ("median_ms", "median [ms]", "{:.3g}"),
    ("residual", "exact residual (max)", "{:.1e}"),
    ("gap_median", "gap median", "{:.2e}"),
    ("gap_min", "gap min", "{:.2e}"),
]


FAILURES_WIDTH = 90
"""Characters of the failures cell: beyond it each status is shortened, its count kept."""


def failures_cell(counts: dict[str, int], width: int = FAILURES_WIDTH) -> str:
    """``status (count); ...`` of the failed solves (``-`` for none), at most about ``width``
    characters: when the statuses are longer, each is cut at a word boundary and ends in ``...``
    (never mid-word, never its count); the JSON records keep them whole."""
    if not counts:
        return "-"
    whole = "; ".join(f"{k} ({v})" for k, v in counts.items())
    if len(whole) > width:
        each = max(16, width // len(counts) - 8)
        whole = "; ".join(f"{shorten(k, each)} ({v})" for k, v in counts.items())
    return whole.replace("|", "\\|")


def shorten(text: str, width: int) -> str:
    """``text`` in one line of at most ``width`` characters, cut at a word boundary with ``...``."""
    text = " ".join(text.split())
    if len(text) <= width:
        return text
    cut = text[: width - 3]
    if text[width - 3] != " " and " " in cut:
        cut = cut.rsplit(" ", 1)[0]
    return cut.rstrip(" ,;:") + "..."


def _versions() -> str:
    found = []
    for pkg in SOLVER_PACKAGES:
        try:
            found.append(f"{pkg} {metadata.version(pkg)}")
        except metadata.PackageNotFoundError:
            continue
    return ", ".join(found)


def _span(values: Sequence[int]) -> str:
    return f"{min(values)}" if min(values) == max(values) else f"{min(values)}-{max(values)}"


def _problem_lines(problems: Sequence[RecordedQP]) -> list[str]:
    by: dict[str, list[RecordedQP]] = {}
    for qp in problems:
        by.setdefault(str(qp.meta["scenario"]), []).append(qp)
    lines = []
    for name, qps in by.items():
        nv = [qp.n_var for qp in qps]
        nr = [qp.n_rows for qp in qps]
        steps = [int(qp.meta["step"]) for qp in qps]
        drones = sorted({int(qp.meta["n"]) for qp in qps})
        lines.append(
            f"  - `{name}`: {len(qps)} QPs (steps {min(steps)}-{max(steps)}), {_span(drones)} drones in the "
            f"QP, d = {qps[0].meta['dim']}, {_span(nv)} variables, {_span(nr)} rows, "
            f"nnz(A) up to {max(qp.A.nnz for qp in qps)}"
        )
    return lines


def markdown_report(bench: SolverBenchmark) -> str:
    """The markdown report of a problem benchmark."""
    refs_ok = sum(r is not None for r in bench.references)
    tl = bench.time_limit_s
    out = [
        "# Solver benchmark on the planner's QPs",
        "",
        f"- Problems: {len(bench.problems)} recorded QPs:",
        *_problem_lines(bench.problems),
        f"- Reference objective f*: {REFERENCE_SOLVER} at eps_abs {REFERENCE_EPS:g} (eps_rel 0), cold: "
        f"{refs_ok}/{len(bench.references)} solved.",
        "- Settings: `default` = each solver's own settings; `low` / `mid` / `high` = eps_abs 1e-3 / 1e-6 / "
        "1e-9 with eps_rel 0, mapped to each solver's parameters.",
        "- Success: found within the time limit, primal residual <= tol and objective gap "
        "|f - f*| / max(1, |f*|) <= tol, with tol = 1e-3 (default, low), 1e-6 (mid), 1e-9 (high).",
        f"- Runtime: wall-clock setup + solve (cold) or update + solve (warm), time limit {tl:g} s. "
        f"`shgeom` = shifted geometric mean with shift {SHIFT_S * 1e3:g} ms, failures counted at the time "
        "limit; `ratio` = shgeom / best shgeom of the table; median and p90 over successful solves.",
        "- Modes: `cold` = fresh setup, no warm start; `warm` = each scenario's sequence replayed as the "
        "planner runs it (set up once, then updated; warm-started from the planner's x0 where the backend "
        "uses one), only for backends that are persistent or warm-start.",
        f"- Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
        f"{platform.python_version()}, OPENBLAS_NUM_THREADS=1; solvers interleaved problem by problem, one "
        f"solve at a time; {_versions()}.",
        f"- Wall time of the benchmark: {bench.wall_s:.0f} s; load average (1 min) {bench.load[0]:.1f} at "
        f"the start, {bench.load[1]:.1f} at the end (the machine is shared: compare ratios within one run).",
        "",
    ]
    for mode in bench.modes:
        out += [f"## {'Cold start' if mode == 'cold' else 'Warm-start replay'}", ""]
        for setting in bench.settings:
            rows = [r for r in bench.rows if (r["mode"], r["setting"]) == (mode, setting)]
            if not rows:
                continue
            rows.sort(key=lambda r: (-r["success_rate"], r["shgeom_runtime_ms"]))
            table = markdown_table(rows, SUMMARY_COLUMNS, {"failures": failures_cell})
            out += [f"### {setting} (tol {TOLERANCES[setting]:g})", "", table, ""]
    if bench.exact:
        out += _exact_section(bench)
    if bench.not_run:
        rows = [{**r, "installed": "yes" if r["installed"] else "no"} for r in bench.not_run]
        columns = [("solver", "solver", "{}"), ("installed", "installed", "{}"), ("note", "why", "{}")]
        out += ["## Not run", "", markdown_table(rows, columns), ""]
    return "\n".join(out)


def _exact_section(bench: SolverBenchmark) -> list[str]:
    by: dict[str, list[tuple[RecordedQP, dict[str, Any], float | None]]] = {}
    for qp, res, ref in zip(bench.problems, bench.exact, bench.references, strict=True):
        by.setdefault(str(qp.meta["scenario"]), []).append((qp, res, ref))
    out = [
        f"## Exact non-convex reference ({EXACT_SOLVER})",
        "",
        "ipopt (tol 1e-6) on the exact problem: the QP's cost and rows with its linearised separation rows "
        "replaced by the true distance constraints at every step, warm-started from the planner's x0 "
        f"(time limit {EXACT_TIME_LIMIT_S:g} s). The gap (f_exact - f_QP*) / max(1, |f_QP*|) is <= 0 (the "
        "linearisation is conservative); its size is the price of convexifying the separation.",
        "",
    ]
    table = []
    for name, items in by.items():
        solved = [(r, ref) for _, r, ref in items if r["found"]]
        gaps = [objective_gap(r["objective"], ref) for r, ref in solved if ref is not None]
        ms = [1e3 * r["runtime_s"] for r, _ in solved]
        table.append(
            {
                "scenario": name,
                "solved": f"{len(solved)}/{len(items)}",
                "median_ms": float(np.median(ms)) if ms else None,
                "residual": max((r["primal_residual"] for r, _ in solved), default=None),
                "gap_median": float(np.median(gaps)) if gaps else None,
                "gap_min": min(gaps, default=None),
            }
        )
    out.append(markdown_table(table, EXACT_COLUMNS))
    out.append("")
    return out


def records(bench: SolverBenchmark) -> list[dict[str, Any]]:
    """The rows of the report as JSON records (``--json``)."""
    return [*bench.rows, *({"mode": None, "setting": None, **r} for r in bench.not_run)]
