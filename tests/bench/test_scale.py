"""``mpcform bench scale`` on tiny sizes: every field measured, budgets, profiles, CLI and bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mpcform.bench.scale import bench_case, profile_case, run
from mpcform.bench.scale_cases import LIMITS
from mpcform.cli.main import main

CASE_FIELDS = (
    "step_ms_median",
    "step_ms_p90",
    "step_ms_max",
    "cpu_ms_p50",
    "cpu_ms_p99",
    "cpu_ms_max",
    "fast_ms_median",
    "fast_ms_p90",
    "fast_cpu_ms_median",
    "rss_peak_mib",
    "rss_delta_mib",
    "planning_s",
    "min_separation_segments",
    "final_tracking_error",
    "max_slack_m",
)


@pytest.mark.parametrize("scenario", ["formation", "crossing"])
def test_bench_case_returns_every_field(scenario: str) -> None:
    row = bench_case(scenario, 8, "decoupled", steps=6, horizon=3, trace_memory=True)
    assert row["steps_run"] == 6 and row["note"] == ""
    assert row["qp_steps"] + row["fast_path_steps"] == 6 and row["fallback_steps"] == 0
    for key in CASE_FIELDS + ("tracemalloc_peak_mib",):
        assert np.isfinite(row[key]), key
    assert row["step_ms_median"] > 0 and row["rss_peak_mib"] > 0 and row["tracemalloc_peak_mib"] > 0
    assert 0 < row["cpu_ms_p50"] <= row["cpu_ms_p99"] <= row["cpu_ms_max"]
    assert 0 <= row["deadline_misses"] <= 6
    assert row["separation_ok"] and row["min_separation_segments"] >= LIMITS.d_min_m
    if row["qp_steps"]:
        assert np.isfinite(row["qp_ms_median"]) and row["qp_drones_max"] >= 1
        assert (
            0
            < row["qp_cpu_ms_median"]
            <= row["qp_cpu_ms_p90"]
            <= row["qp_cpu_ms_p99"]
            <= row["qp_cpu_ms_max"]
        )


def test_the_solver_floor_of_a_crossing_is_within_its_steps() -> None:
    row = bench_case("crossing", 10, "decoupled", steps=5)
    assert 1 <= row["solver_steps"] <= row["qp_steps"] + row["fallback_steps"]
    assert 0 < row["solver_ms_median"] <= row["solved_ms_median"]
    assert np.isfinite(row["solver_ratio"]) and row["solver_ratio"] >= 1.0


def test_a_sparse_mode_counts_its_solver_calls_too() -> None:
    row = bench_case("crossing", 6, "decoupled-sparse", steps=3, horizon=4)
    assert row["solver"] == "piqp" and row["solver_steps"] >= 1 and row["solver_ratio"] >= 1.0


def test_profile_case_lists_the_planner_step_functions() -> None:
    text = profile_case("crossing", 10, "decoupled", steps=4, horizon=5)
    header = text.splitlines()[0]
    assert header == (
        "# bench scale: crossing n=10 decoupled (daqp (per drone)): 4 planner steps profiled "
        "(a second run, not timed)"
    )
    assert "Ordered by: internal time" in text and "per_drone.py" in text and "daqp_dense.py" in text
    setup = ("(make_case)", "(crossing_case)", "(lattice)")  # the case's set-up is not profiled
    assert not any(name in text for name in setup)  # (its reference's targets are: the step asks them)


def test_crossing_has_qp_steps_and_formation_flight_takes_the_fast_path() -> None:
    cross = bench_case("crossing", 12, "decoupled", steps=10, horizon=5)
    form = bench_case("formation", 12, "decoupled", steps=12, horizon=3)
    assert cross["qp_steps"] > 0 and cross["qp_ms_median"] > 0
    # from rest the default a_max ramps the first commands (QP steps), then the fast path flies it
    assert form["qp_steps"] <= 2 and form["fast_path_steps"] == 12 - form["qp_steps"]


def test_run_in_process_skips_monolithic_sizes_after_the_budget() -> None:
    said: list[tuple[str, int, int]] = []
    rows = run(
        [6, 8],
        ["crossing"],
        "decoupled",
        steps=3,
        horizon=3,
        monolithic_budget_s=1e-9,
        isolate=False,
        progress=lambda *line: said.append(line),
    )
    assert [(i, n) for _, i, n in said] == [(1, 4), (2, 4), (3, 4), (4, 4)]  # a line per case, skipped too
    assert said[0][0] == "crossing n=6 decoupled (DAQP)" and said[3][0] == "crossing n=8 monolithic (skipped)"
    assert [(r["n"], r["mode"]) for r in rows] == [
        (6, "decoupled"),
        (6, "monolithic"),
        (8, "decoupled"),
        (8, "monolithic"),
    ]
    assert rows[1]["steps_run"] == 1 and "stopped after 1 of 3" in rows[1]["note"]
    assert rows[3]["steps_run"] == 0 and rows[3]["note"].startswith("skipped: n = 6")


def test_run_profiles_each_case_run_into_one_file(tmp_path: Path) -> None:
    out = tmp_path / "profile.txt"
    rows = run([6, 8], ["crossing"], "decoupled", steps=3, horizon=3, monolithic_budget_s=0, profile_path=out)
    headers = [line for line in out.read_text().splitlines() if line.startswith("# ")]
    assert [r["n"] for r in rows] == [6, 8] and all("profile" not in r for r in rows)
    assert headers == [
        f"# bench scale: crossing n={n} decoupled (daqp (per drone)): 3 planner steps profiled "
        "(a second run, not timed)"
        for n in (6, 8)
    ]


def test_cli_bench_scale_writes_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "scale.json"
    argv = [
        "bench",
        "scale",
        "--n",
        "6",
        "--steps",
        "2",
        "--horizon",
        "3",
        "--scenario",
        "formation",
        "--monolithic-budget",
        "0",
        "--in-process",
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    records = json.loads(out.read_text())
    assert [r["table"] for r in records] == ["cases", "growth"] and records[0]["n"] == 6
    text = capsys.readouterr().out
    assert "| formation | 6 | decoupled |" in text and "| step / solver |" in text


def test_bad_sizes_fail_before_any_case(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "scale", "--n", "1", "--scenario", "crossing"]) == 2
    assert "n >= 2" in capsys.readouterr().err
    assert main(["bench", "scale", "--n", "4", "--horizon", "0"]) == 2
    assert "controller.horizon" in capsys.readouterr().err
