"""Accuracy settings and the success rule: gaps, the exact solver's exception, per-group summaries."""

from __future__ import annotations

import math
from typing import Any

import pytest

from mpcform.bench.accuracy import (
    EXACT_SOLVER,
    default_solvers,
    objective_gap,
    options_for,
    succeeded,
    summarize,
)
from mpcform.bench.stats import shifted_geometric_mean


def _res(**kw: Any) -> dict[str, Any]:
    base = {
        "index": 0,
        "solver": "s",
        "setting": "mid",
        "mode": "cold",
        "found": True,
        "status": "ok",
        "runtime_s": 0.01,
        "objective": -100.0,
        "primal_residual": 1e-8,
    }
    return {**base, **kw}


def test_success_rule() -> None:
    assert succeeded(_res(), -100.0, 1.0)
    assert not succeeded(_res(found=False), -100.0, 1.0)
    assert not succeeded(_res(runtime_s=2.0), -100.0, 1.0)  # over the time limit
    assert not succeeded(_res(primal_residual=1e-5), -100.0, 1.0)
    assert not succeeded(_res(objective=-100.01), -100.0, 1.0)  # gap 1e-4 > 1e-6
    assert succeeded(_res(objective=-100.0001, setting="low"), -100.0, 1.0)
    assert succeeded(_res(solver=EXACT_SOLVER, objective=-101.0), -100.0, 1.0)  # exact: gap not judged


def test_summary_counts_failures_at_the_time_limit() -> None:
    results = [_res(index=0), _res(index=1, found=False, status="max iter", runtime_s=0.5)]
    (row,) = summarize(results, [-100.0, -100.0], 1.0)
    assert row["success_rate"] == 50.0 and row["failures"] == {"max iter": 1}
    assert row["shgeom_runtime_ms"] == pytest.approx(1e3 * shifted_geometric_mean([0.01, 1.0]))
    assert row["median_runtime_ms"] == pytest.approx(10.0) and row["shgeom_ratio"] == 1.0


def test_objective_gap_is_relative_to_max_one_and_the_reference() -> None:
    assert objective_gap(-101.0, -100.0) == pytest.approx(-0.01)
    assert objective_gap(0.5, 0.25) == pytest.approx(0.25)  # |f*| < 1: absolute gap
    assert math.isnan(objective_gap(None, -100.0)) and math.isnan(objective_gap(1.0, None))


def test_options_of_a_setting_and_the_default_solvers() -> None:
    default, high = options_for(None, 2.0), options_for(1e-9, 2.0)
    assert (default.eps_abs, default.eps_rel, default.time_limit_s) == (None, None, 2.0)
    assert (high.eps_abs, high.eps_rel, high.time_limit_s) == (1e-9, 0.0, 2.0)
    assert EXACT_SOLVER not in default_solvers() and "piqp" in default_solvers()
