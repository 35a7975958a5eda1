"""``mpcform bench scale`` on tiny sizes, the growth-exponent fit, and a 200-drone decoupled crossing."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mpcform.bench.scale import (
    LIMITS,
    SPACING_M,
    bench_case,
    crossing_case,
    formation_case,
    growth_exponent,
    growth_rows,
    markdown_table,
    mode_settings,
    report,
    run,
    two_point_exponent,
)
from mpcform.cli.main import main
from mpcform.formation.geometry import min_pair_distance, min_segment_distance
from mpcform.mpc.planner import MPCPlanner

CASE_FIELDS = (
    "step_ms_median", "step_ms_p90", "step_ms_max", "fast_ms_median", "fast_ms_p90", "rss_peak_mib",
    "rss_delta_mib", "planning_s", "min_separation_segments", "final_tracking_error", "max_slack_m",
)  # fmt: skip


@pytest.mark.parametrize("scenario", ["formation", "crossing"])
def test_bench_case_returns_every_field(scenario: str) -> None:
    row = bench_case(scenario, 8, "decoupled", steps=6, horizon=3, trace_memory=True)
    assert row["steps_run"] == 6 and row["note"] == ""
    assert row["qp_steps"] + row["fast_path_steps"] == 6 and row["fallback_steps"] == 0
    for key in CASE_FIELDS + ("tracemalloc_peak_mib",):
        assert np.isfinite(row[key]), key
    assert row["step_ms_median"] > 0 and row["rss_peak_mib"] > 0 and row["tracemalloc_peak_mib"] > 0
    assert row["separation_ok"] and row["min_separation_segments"] >= LIMITS.d_min_m
    if row["qp_steps"]:
        assert np.isfinite(row["qp_ms_median"]) and row["qp_drones_max"] >= 1


def test_crossing_has_qp_steps_and_formation_flight_takes_the_fast_path() -> None:
    cross = bench_case("crossing", 12, "decoupled", steps=10, horizon=5)
    form = bench_case("formation", 12, "decoupled", steps=8, horizon=3)
    assert cross["qp_steps"] > 0 and cross["qp_ms_median"] > 0
    assert form["fast_path_steps"] == 8 and math.isnan(form["qp_ms_median"])


def test_cases_have_constant_density_and_reference_speeds_below_v_max() -> None:
    for n in (10, 100, 1000):
        ref, p0 = formation_case(n)
        assert p0.shape == (n, 3) and min_pair_distance(ref.template.offsets) == pytest.approx(SPACING_M)
        _, vel = ref.targets(np.linspace(0.0, 3.0, 4))
        assert np.linalg.norm(vel, axis=-1).max() < 0.6 * LIMITS.v_max_mps
        ref, p0 = crossing_case(n)
        assert p0.shape == (n, 3) and min_pair_distance(p0) >= SPACING_M - 1e-9
        _, vel = ref.targets(np.array([0.0, 1.0]))
        assert np.allclose(np.abs(vel[..., 0]), 0.5) and np.allclose(vel[..., 1:], 0.0)
        assert vel[0, :, 0].sum() == pytest.approx(0.0, abs=0.5 + 1e-12)  # the halves fly head-on


def test_growth_exponent_fits_synthetic_power_laws() -> None:
    rng = np.random.default_rng(3)
    n = np.array([10, 30, 100, 300, 1000, 100, 300, 1000])
    t = 0.02 * n**1.3 * np.exp(rng.normal(0.0, 0.01, n.shape))
    t[:2] = 1e3  # points below n = 100 are ignored
    assert growth_exponent(n, t) == pytest.approx(1.3, abs=0.03)
    assert two_point_exponent([100, 1000], [5.0, 50.0]) == pytest.approx(1.0)
    assert two_point_exponent([100, 1000], [5.0, 5.0 * 10**1.2]) == pytest.approx(1.2)
    assert math.isnan(growth_exponent([10, 30, 100], [1.0, 2.0, 3.0]))  # one point at n >= 100
    assert math.isnan(two_point_exponent([100, 300], [1.0, 2.0]))
    assert math.isnan(growth_exponent([100, 1000], [1.0, float("nan")]))


def test_growth_rows_per_scenario_and_mode() -> None:
    rows = [
        {"scenario": "crossing", "mode": "decoupled", "n": n, "steps": 10, "steps_run": 10,
         "step_ms_median": 0.1 * n, "qp_ms_median": 0.01 * n**1.5}
        for n in (100, 300, 1000)
    ]  # fmt: skip
    rows[-1]["steps_run"] = 4
    (g,) = growth_rows(rows)
    assert g["step_exponent_fit"] == pytest.approx(1.0) and g["step_exponent_100_1000"] == pytest.approx(1.0)
    assert g["qp_exponent_fit"] == pytest.approx(1.5) and g["partial"] == [1000]


def test_run_in_process_skips_monolithic_sizes_after_the_budget() -> None:
    rows = run([6, 8], ["crossing"], "decoupled", steps=3, horizon=3, monolithic_budget_s=1e-9, isolate=False)
    assert [(r["n"], r["mode"]) for r in rows] == [(6, "decoupled"), (6, "monolithic"), (8, "decoupled"),
                                                   (8, "monolithic")]  # fmt: skip
    assert rows[1]["steps_run"] == 1 and "stopped after 1 of 3" in rows[1]["note"]
    assert rows[3]["steps_run"] == 0 and rows[3]["note"].startswith("skipped: n = 6")
    text, growth = report(rows, "decoupled")
    assert text.count("| crossing |") == 4 + len(growth) and "not measured" in text
    assert markdown_table(rows).splitlines()[-1].count(" - ") > 5  # a skipped row shows dashes


def test_mode_settings() -> None:
    assert (
        mode_settings("monolithic", 4).grouping is False
        and mode_settings("monolithic", 4).coupling == "joint"
    )
    assert mode_settings("decoupled", 4).grouping and mode_settings("decoupled", 4).horizon == 4
    with pytest.raises(ValueError):
        mode_settings("nope", 4)


def test_cli_bench_scale_writes_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "scale.json"
    argv = ["bench", "scale", "--n", "6", "--steps", "2", "--horizon", "3", "--scenario", "formation",
            "--monolithic-budget", "0", "--in-process", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    records = json.loads(out.read_text())
    assert [r["table"] for r in records] == ["cases", "growth"] and records[0]["n"] == 6
    assert "| formation | 6 | decoupled |" in capsys.readouterr().out


def test_decoupled_crossing_of_200_drones_keeps_separation_along_segments() -> None:
    ref, p = crossing_case(200, gap_m=0.9)  # fronts close enough to conflict at once
    planner = MPCPlanner(ref, 0.1, LIMITS, mode_settings("decoupled", 3))
    planner.reset(0.0, p)
    modes = []
    for j in range(10):
        out = planner.step(0.1 * j, p)
        p_next = p + 0.1 * out.command_mps
        assert min_segment_distance(p, p_next) >= LIMITS.d_min_m * (1 - 1e-9)
        assert np.linalg.norm(out.command_mps, axis=1).max() <= LIMITS.v_max_mps * (1 + 1e-9)
        modes.append(out.info.mode)
        p = p_next
    assert modes.count("qp") >= 5 and "fallback" not in modes


def test_bad_sizes_fail_before_any_case(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "scale", "--n", "1", "--scenario", "crossing"]) == 2
    assert "n >= 2" in capsys.readouterr().err
    assert main(["bench", "scale", "--n", "4", "--horizon", "0"]) == 2
    assert "controller.horizon" in capsys.readouterr().err
