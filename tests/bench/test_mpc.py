"""``mpcform bench mpc`` on tiny cases: every column is measured in wall and CPU time, setups count
in the raw floor, scenario files run as they are, cvxpy stays within its budget and the JSON
records match."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mpcform.bench.mpc import (
    RecordingBackend,
    bench_case,
    check_cases,
    cpu_key,
    generated_case,
    markdown_table,
    run,
    scenario_case,
    swap_case,
)
from mpcform.cli.main import main
from mpcform.errors import ValidationError
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend

ROOT = Path(__file__).resolve().parents[2]
TIMES = ("qp", "raw", "fast", "rollout")


def test_recording_backend_keeps_every_problem_and_solves_like_its_inner_backend() -> None:
    from mpcform.mpc.planner import MPCPlanner
    from mpcform.world.limits import Limits

    ref, start = swap_case(4, 2)
    rec = RecordingBackend(make_backend("piqp", SolverOptions()))
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), solver=rec)
    planner.reset(0.0, start)
    infos = [planner.step(0.0, start).info]
    assert infos[0].mode == "qp" and len(rec.problems) == 1 and rec.problems[0]["setup"]
    pb = rec.problems[0]
    assert pb["A"].nnz == pb["Ax"].shape[0] and pb["l"].shape == pb["u"].shape == (pb["A"].shape[0],)


def test_bench_case_measures_qp_fast_path_and_references_in_wall_and_cpu_time() -> None:
    row = bench_case(generated_case(4, 2, 60, "joint"), solver="piqp", cvxpy_solver=None)
    assert row["qp_steps"] + row["fast_path_steps"] + row["fallback_steps"] == 60
    assert row["qp_steps"] > 0 and row["fast_path_steps"] > 0 and row["setups"] >= 1
    timed = [f"{t}_ms_{stat}" for t in TIMES for stat in ("median", "p90")]
    for key in ("overhead", "fast_ratio", "whole_s", *timed):
        for k in (key, cpu_key(key)):
            assert np.isfinite(row[k]) and row[k] > 0, k
    table = markdown_table([row])
    assert table.count("\n") == 4 and "swap planar" in table and table.endswith("wall / CPU (process time).")
    assert f"| {row['qp_ms_median']:.2f} / {row['qp_cpu_ms_median']:.2f} |" in table


def test_decoupled_floor_is_the_bare_daqp_calls() -> None:
    row = bench_case(generated_case(6, 2, 40, "decoupled"), solver="piqp", cvxpy_solver=None)
    assert row["solver"] == "daqp (per drone)" and row["qp_steps"] > 0 and row["setups"] == 0
    assert 0 < row["raw_ms_median"] < row["qp_ms_median"]
    assert 0 < row["raw_cpu_ms_median"] < row["qp_cpu_ms_median"]
    assert row["overhead"] > 1 and row["overhead_cpu"] > 1


def test_scenario_case_runs_the_file_as_it_is_in_the_chosen_mode() -> None:
    case = scenario_case(ROOT / "scenarios" / "swap_planar_8.toml", "decoupled")
    assert case.name == "swap_planar_8" and case.steps == 120 and case.dt_s == 0.1
    assert case.start_m.shape == (8, 2) and case.limits.d_min_m == 0.5
    assert case.settings.coupling == "decoupled" and case.settings.solves_per_drone
    joint = scenario_case(ROOT / "scenarios" / "swap_planar_8.toml", "joint").settings
    assert joint.coupling == "joint" and joint.grouping and not joint.solves_per_drone
    with pytest.raises(ValidationError, match="ideal plant.*'quadrotor'"):
        scenario_case(ROOT / "scenarios" / "swap_spatial_12_quadrotor_wind.toml", "joint")


def test_cvxpy_runs_within_its_budget_and_is_skipped_with_the_reason_beyond() -> None:
    pytest.importorskip("cvxpy")
    case = generated_case(3, 2, 12, "joint")
    row = bench_case(case, "piqp", "piqp", cvxpy_budget_s=60.0)
    assert "cvxpy_skipped" not in row and row["cvxpy_ms_median"] > 0 and row["cvxpy_cpu_ms_median"] > 0
    assert row["cvxpy_whole_s"] > 0 and np.isfinite(row["cvxpy_speedup_whole_cpu"])
    tight = bench_case(case, "piqp", "piqp", cvxpy_budget_s=1e-6)
    assert "budget 1e-06 s" in tight["cvxpy_skipped"] and "cvxpy_ms_median" not in tight
    assert "cvxpy skipped for swap planar (n = 3): estimated" in markdown_table([tight])


def test_cpu_key_names_the_twin_of_every_paired_column() -> None:
    assert cpu_key("qp_ms_median") == "qp_cpu_ms_median"
    assert cpu_key("cvxpy_whole_s") == "cvxpy_whole_cpu_s"
    assert cpu_key("cvxpy_speedup_qp") == "cvxpy_speedup_qp_cpu"


def test_cli_bench_mpc_writes_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rows.json"
    argv = [
        "bench",
        "mpc",
        "--n",
        "3",
        "--spatial-n",
        "--steps",
        "5",
        "--scenarios",
        "--cvxpy-budget",
        "0",
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    records = json.loads(out.read_text())
    assert [r["n"] for r in records] == [3] and "| case |" in capsys.readouterr().out
    assert "qp_cpu_ms_median" in records[0] and "cvxpy_ms_median" not in records[0]


def test_cli_bench_mpc_refuses_a_negative_budget(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "mpc", "--cvxpy-budget", "-1"]) == 2
    assert "expected a number of seconds >= 0" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("planar", "spatial", "steps", "scenarios", "match"),
    [
        ([0], [], 60, [], "swaps of >= 2 drones"),  # was a ZeroDivisionError
        ([8], [20], 0, [], ">= 1 step"),
        ([], [], 60, [], "no case to run"),
    ],
)
def test_bad_sizes_fail_before_any_case(planar, spatial, steps, scenarios, match) -> None:  # noqa: ANN001
    with pytest.raises(ValidationError, match=match):
        run(planar, spatial, steps, "piqp", "joint", 0.0, scenarios)


def test_check_cases_builds_the_scenario_cases_before_any_runs() -> None:
    swap = Path(__file__).resolve().parents[2] / "scenarios" / "swap_planar_8.toml"
    (case,) = check_cases([4], [], 3, [swap], "decoupled")
    assert case.name == "swap_planar_8" and case.settings.coupling == "decoupled"
    with pytest.raises(ValidationError, match="no case to run"):
        check_cases([], [], 3, [], "joint")
