"""bench online: the crossing planned online, its step times, deadline misses, solver floor,
growth exponent and profile."""

from __future__ import annotations

import math
from pathlib import Path

from mpcform.bench.online import bench_online, growth, markdown_table, profile_online, run


def test_a_small_crossing_meets_its_deadline_and_keeps_d_min() -> None:
    row = bench_online(8, 40, 0.1)
    assert row["deadline_miss_share"] == 0.0 and row["overrun_max_ms"] == 0.0
    assert row["wall_p50_ms"] <= row["wall_p99_ms"] <= row["wall_max_ms"] < 100.0
    assert row["cpu_p50_ms"] <= row["cpu_p99_ms"] <= row["cpu_max_ms"]
    assert row["min_distance_m"] >= 0.5 - 1e-9
    assert "largest n with wall p99 < budget and no deadline miss: 8" in markdown_table([row])


def test_the_solver_floor_of_a_crossing_is_within_its_steps() -> None:
    row = bench_online(10, 8, 0.1)
    assert 1 <= row["solver_steps"] <= 8
    assert 0 < row["solver_ms_median"] <= row["solved_wall_p50_ms"]
    assert math.isfinite(row["solver_ratio"]) and row["solver_ratio"] >= 1.0


def test_an_impossible_deadline_is_missed_and_reported() -> None:
    row = bench_online(8, 20, 1e-9)
    assert row["deadline_miss_share"] > 0.0 and row["overrun_max_ms"] > 0.0
    assert row["min_distance_m"] >= 0.5 - 1e-9  # the braking fallback keeps d_min
    assert "no deadline miss: none\n" in markdown_table([row])


def test_the_cpu_p50_growth_exponent_is_fitted_over_n_from_100() -> None:
    rows = [
        {"n": n, "coupling": "decoupled", "cpu_p50_ms": t, "wall_p99_ms": 1.0, "budget_s": 0.1}
        | {"deadline_miss_share": 0.0}
        for n, t in ((20, 50.0), (100, 1.0), (1000, 10.0))  # the n < 100 point left out of the fit
    ]
    record = growth(rows)
    assert record["table"] == "growth" and record["sizes"] == [20, 100, 1000]
    assert math.isclose(record["cpu_p50_exponent_fit"], 1.0)
    assert markdown_table(rows).endswith("growth exponent of the CPU p50 over n (fit n>=100): 1.00")
    assert math.isnan(growth(rows[:2])["cpu_p50_exponent_fit"])
    assert markdown_table(rows[:2]).endswith("(fit n>=100): - (needs two sizes >= 100)")


def test_profile_online_lists_the_planner_step_functions() -> None:
    text = profile_online(10, 4, 0.1)
    assert text.splitlines()[0] == (
        "# bench online: crossing n=10 (decoupled, deadline 0.1 s): 4 online steps profiled "
        "(a second run, not timed)"
    )
    assert "Ordered by: internal time" in text and "per_drone.py" in text and "daqp_dense.py" in text


def test_run_writes_a_section_per_case(tmp_path: Path) -> None:
    out = tmp_path / "online.prof"
    rows = run((4, 6), 3, 0.1, profile_path=out)
    assert [r["n"] for r in rows] == [4, 6] and all(r["table"] == "cases" for r in rows)
    headers = [line for line in out.read_text().splitlines() if line.startswith("# ")]
    assert [h.split(":")[1] for h in headers] == [
        " crossing n=4 (decoupled, deadline 0.1 s)",
        " crossing n=6 (decoupled, deadline 0.1 s)",
    ]
