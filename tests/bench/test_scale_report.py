"""``mpcform bench scale``'s report: the cases' tables, the growth exponents and the target lines."""

from __future__ import annotations

import math
from typing import Any

import pytest

from mpcform.bench.scale import run
from mpcform.bench.scale_report import TIMING_COLUMNS, markdown_table, report, target_lines


@pytest.fixture(scope="module")
def rows() -> list[dict[str, Any]]:
    """A decoupled crossing at 6 and 8 drones, its monolithic case at 6 over budget, at 8 skipped."""
    return run([6, 8], ["crossing"], "decoupled", steps=3, horizon=3, monolithic_budget_s=1e-9, isolate=False)


def test_the_report_has_the_cases_their_timing_the_growth_and_the_targets(rows: list[dict[str, Any]]) -> None:
    text, growth = report(rows, "decoupled")
    assert text.count("| crossing |") == 2 * 4 + len(growth) and "not measured" in text
    assert "median CPU per QP step" in text and all("qp_cpu_exponent_fit" in g for g in growth)
    assert all("cpu_exponent_fit" in g for g in growth)
    assert "| CPU p50 [ms] | CPU p99 | CPU max |" in text and "| step / solver |" in text
    assert markdown_table(rows).splitlines()[-1].count(" - ") > 5  # a skipped row shows dashes
    timing = markdown_table(rows, TIMING_COLUMNS).splitlines()
    assert timing[2].startswith("| crossing | 6 | decoupled | 3 |")


def _crossing_1000(**measured: float) -> dict[str, Any]:
    row = {"scenario": "crossing", "n": 1000, "mode": "decoupled", "steps": 30, "steps_run": 30, "note": ""}
    return row | measured


def test_the_1000_drone_p99_and_solver_ratio_targets() -> None:
    row = _crossing_1000(qp_cpu_ms_p99=80.0, solver_ratio=3.5, solved_ms_median=70.0, solver_ms_median=20.0)
    lines = target_lines([row], [], "decoupled")
    assert "crossing n=1000 p99 QP step CPU 80.0 ms <= 100 ms: met" in lines
    assert (
        "crossing n=1000 ratio to the bare solver at the median 3.50 (step 70.0 ms, solver 20.0 ms) "
        "<= 3: MISSED" in lines
    )
    over = target_lines([_crossing_1000(qp_cpu_ms_p99=120.0, solver_ratio=2.0)], [], "decoupled")
    assert any(line.endswith("<= 100 ms: MISSED") and "p99" in line for line in over)
    assert any(line.startswith("crossing n=1000 ratio") and line.endswith(": met") for line in over)


def test_targets_not_measured_without_the_case() -> None:
    lines = target_lines([_crossing_1000(qp_cpu_ms_p99=math.nan)], [], "decoupled")
    assert "crossing n=1000 p99 QP step CPU - ms <= 100 ms: not measured" in lines
    assert any(line.startswith("crossing n=1000 ratio") and line.endswith("not measured") for line in lines)
