"""The report of ``mpcform bench solvers``: tables per mode and setting, ranked; not-run solvers; records."""

from __future__ import annotations

from pathlib import Path

from mpcform.bench.problems import load_problems
from mpcform.bench.report import failures_cell, markdown_report, records, shorten
from mpcform.bench.solvers import SolverBenchmark

ROOT = Path(__file__).resolve().parents[2]


def _row(solver: str, success: float, shgeom_ms: float) -> dict[str, object]:
    return {
        "solver": solver,
        "mode": "cold",
        "setting": "mid",
        "problems": 2,
        "success_rate": success,
        "shgeom_runtime_ms": shgeom_ms,
        "shgeom_ratio": 1.0,
        "median_runtime_ms": shgeom_ms,
        "p90_runtime_ms": shgeom_ms,
        "primal_residual_max": 1e-9,
        "objective_gap_max": 1e-8,
        "found": 2,
        "failures": {"max iter": 1} if success < 100 else {},
    }


def _bench() -> SolverBenchmark:
    problems = load_problems(ROOT / "problems")[:2]
    rows = [_row("slow", 100.0, 5.0), _row("flaky", 50.0, 0.1), _row("fast", 100.0, 1.0)]
    gone = {"solver": "gone", "installed": False, "supported": False, "success_rate": 0.0, "note": "absent"}
    return SolverBenchmark(problems, rows, [-1.0, None], [], [gone], ["mid"], ["cold"], 1.0, 12.0, (0.5, 0.7))


def test_report_ranks_by_success_then_speed_and_lists_what_did_not_run() -> None:
    text = markdown_report(_bench())
    assert "## Cold start" in text and "### mid (tol 1e-06)" in text and "Warm-start" not in text
    firsts = [line.split(" | ")[0] for line in text.splitlines() if line.startswith("| ")]
    ranked = [cell.removeprefix("| ") for cell in firsts if cell not in ("| solver", "| ---")]
    assert ranked == ["fast", "slow", "flaky", "gone"]
    assert "max iter (1)" in text and "cold: 1/2 solved" in text and "## Not run" in text
    assert "Exact non-convex" not in text  # no exact results: no section


def test_records_list_the_rows_then_the_solvers_not_run() -> None:
    bench = _bench()
    recs = records(bench)
    assert recs[:3] == bench.rows
    assert recs[3]["solver"] == "gone" and recs[3]["mode"] is None and recs[3]["setting"] is None


def test_the_failures_cell_is_whole_or_cut_at_words_with_every_count() -> None:
    assert failures_cell({}) == "-"
    assert failures_cell({"max iter": 2, "time limit": 1}) == "max iter (2); time limit (1)"
    long = {
        "osqp: maximum iterations reached before the primal residual met the tolerance": 4,
        "qpsolvers: solver returned no solution (infeasible or unbounded problem)": 2,
        "a|b": 1,
    }
    cell = failures_cell(long)
    parts = cell.split("; ")
    assert [p.rsplit(" (", 1)[1] for p in parts] == ["4)", "2)", "1)"]  # every count, whole
    for part, status in zip(parts[:2], long, strict=False):
        shown = part.rsplit(" (", 1)[0]
        assert shown.endswith("...") and status.startswith(shown.removesuffix("..."))
        assert status[len(shown) - 3] == " "  # cut before a space: never mid-word
    assert parts[2] == "a\\|b (1)"  # a pipe does not break the table


def test_shorten() -> None:
    assert shorten("short", 10) == "short"
    assert shorten("one two three four", 12) == "one two..."
    assert shorten("abcdefghijklmnop", 8) == "abcde..."  # one long word: cut inside it
