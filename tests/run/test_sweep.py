"""``mpcform sweep``: jobs and their limit, overrides, parallel runs and their aggregation."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers import tiny_swap_toml

from mpcform.cli.main import main
from mpcform.errors import ScenarioError, ValidationError
from mpcform.run.sweep import (
    MAX_RUNS,
    SweepJob,
    aggregate,
    apply_overrides,
    build_jobs,
    failures_text,
    load_job,
    markdown_table,
    run_sweep,
)

TINY = tiny_swap_toml("tiny", radius_m=1.0, horizon=4, duration_s=0.6)


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def test_apply_overrides_sets_nested_keys_on_a_copy() -> None:
    data = {"controller": {"horizon": 4}, "obstacles": [{"radius": 1.0}]}
    out = apply_overrides(
        data, [("controller.horizon", 8), ("initial.perturbation", 0.1), ("obstacles.0.radius", 2)]
    )
    assert out == {
        "controller": {"horizon": 8},
        "initial": {"perturbation": 0.1},
        "obstacles": [{"radius": 2}],
    }
    assert data["controller"]["horizon"] == 4 and data["obstacles"][0]["radius"] == 1.0
    with pytest.raises(ValidationError, match="not an index"):
        apply_overrides(data, [("obstacles.3.radius", 1.0)])
    with pytest.raises(ValidationError, match="not a table"):
        apply_overrides(data, [("controller.horizon.x", 1)])


def test_jobs_are_the_product_of_sets_and_seeds(tiny: Path) -> None:
    jobs = build_jobs(tiny, [0, 1, 2], [("controller.horizon", [3, 4]), ("initial.perturbation", [0.05])])
    assert len(jobs) == 6 and {j.seed for j in jobs} == {0, 1, 2}
    assert jobs[0].overrides == (("controller.horizon", 3), ("initial.perturbation", 0.05))
    scenario = load_job(jobs[4])
    assert scenario.seed == 1 and scenario.controller.mpc.horizon == 4 and scenario.source == tiny
    assert [j.seed for j in build_jobs(tiny, None, [])] == [None]


def test_parallel_sweep_matches_serial_and_aggregates(tiny: Path) -> None:
    jobs = build_jobs(tiny, [0, 1], [("controller.horizon", [3, 4])])[:3]
    jobs = [SweepJob(j.path, j.overrides + (("initial.perturbation", 0.05),), j.seed) for j in jobs]
    seen: list[int] = []
    parallel = run_sweep(jobs, workers=2, progress=lambda done, total: seen.append(done))
    serial = run_sweep(jobs, workers=1)
    assert seen == [1, 2, 3] and [r["seed"] for r in parallel] == [0, 1, 0]
    for a, b in zip(parallel, serial, strict=True):
        assert a["error"] is None and a["params"] == b["params"]
        assert a["final_tracking_error"] == b["final_tracking_error"]  # same run in a worker process
        assert a["min_separation_segments"] == b["min_separation_segments"] >= 0.5 * (1 - 1e-9)
    groups = aggregate(parallel)
    assert [g["runs"] for g in groups] == [2, 1]
    assert groups[0]["params"] == {"controller.horizon": 3, "initial.perturbation": 0.05}
    for g, runs in zip(groups, (parallel[:2], parallel[2:]), strict=True):
        assert g["successes"] == sum(r["success"] for r in runs)
        assert g["min_separation_segments"] == min(r["min_separation_segments"] for r in runs)
        assert g["final_tracking_error_max"] == max(r["final_tracking_error"] for r in runs)
    assert "controller.horizon=3, initial.perturbation=0.05" in markdown_table(groups)


def test_aggregate_counts_errors_and_failed_checks() -> None:
    def rec(seed: int, ok: bool, err: float, checks: list[str]) -> dict[str, object]:
        return {
            "params": {"a": 1},
            "seed": seed,
            "success": ok,
            "error": None,
            "failed_checks": checks,
            "final_tracking_error": err,
            "max_tracking_error": 2 * err,
            "min_separation_segments": 0.5 + err,
            "separation_violations": 0,
            "speed_violations": 0,
            "solver_failures": 1,
            "step_ms_median": 1.0 + seed,
            "qp_ms_median": float("nan"),
            "qp_ms_p90": float("nan"),
            "wall_s": 1.0,
        }

    records = [
        rec(0, True, 0.01, []),
        rec(1, False, 0.3, ["tracking"]),
        rec(2, True, 0.02, []),
        {"params": {"a": 1}, "seed": 3, "success": False, "error": "MPCFormError: boom", "wall_s": 0.5},
    ]
    (g,) = aggregate(records)
    assert g["runs"] == 4 and g["successes"] == 2 and g["success_rate"] == 0.5 and g["errors"] == 1
    assert g["final_tracking_error_median"] == pytest.approx(0.02) and g["final_tracking_error_max"] == 0.3
    assert g["min_separation_segments"] == pytest.approx(0.51) and g["solver_failures"] == 3
    assert g["step_ms_median"] == 2.0 and g["qp_ms_median"] != g["qp_ms_median"] and g["wall_s"] == 3.5
    text = failures_text(records)
    assert "a=1 seed 1: failed tracking" in text and "seed 3: MPCFormError: boom" in text


def test_a_bad_override_fails_before_any_run(tiny: Path) -> None:
    jobs = build_jobs(tiny, [0], [("controller.horizont", [3])])
    with pytest.raises(ScenarioError, match="horizont"):
        run_sweep(jobs, workers=2)


def test_cli_sweep(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sweep.json"
    argv = ["sweep", str(tiny), "--seeds", "0..1", "--set", "controller.horizon=3", "--json", str(out)]
    assert main(argv) == 0
    records = json.loads(out.read_text())
    assert [r["table"] for r in records] == ["groups", "runs", "runs"]
    assert "| controller.horizon=3 | 2 |" in capsys.readouterr().out
    assert main(["sweep", str(tiny), "--set", "controller.horizon"]) == 2
    assert "--set" in capsys.readouterr().err


def test_a_list_valued_set_sweeps(tiny: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A TOML list as a ``--set`` value (e.g. a wind vector) is one value of that key."""
    argv = ["sweep", str(tiny), "--seeds", "0..1", "--set", "initial.centroid=[0.1, 0.0],[0.0, 0.1]"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "| initial.centroid=[0.1, 0.0] | 2 |" in out and "| initial.centroid=[0.0, 0.1] | 2 |" in out


def test_dask_executor_runs_the_same_jobs(tiny: Path) -> None:
    distributed = pytest.importorskip("dask.distributed")
    jobs = build_jobs(tiny, [0, 1], [])
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False) as cluster:
        records = run_sweep(jobs, executor="dask", scheduler=cluster.scheduler_address)
    assert [r["seed"] for r in records] == [0, 1] and all(r["error"] is None for r in records)


@pytest.mark.parametrize("tol", [-1.0, float("nan"), float("inf")])
def test_a_negative_or_undefined_tolerance_is_refused(tiny: Path, tol: float) -> None:
    with pytest.raises(ValidationError, match=r"^--tol: expected a final tracking error >= 0"):
        build_jobs(tiny, None, [], tolerance_m=tol)
    assert build_jobs(tiny, None, [], tolerance_m=0.0)[0].tolerance_m == 0.0


def test_cli_tol_minus_one(tiny: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", str(tiny), "--tol", "-1"]) == 2
    expected = "mpcform: error: --tol: expected a final tracking error >= 0 [m], got -1.0"
    assert capsys.readouterr().err.strip() == expected


def test_a_combination_too_large_fails_before_any_run(tiny: Path, capsys: pytest.CaptureFixture[str]) -> None:
    jobs = build_jobs(tiny, None, [("simulation.duration", [0.6, 1e9])])
    with pytest.raises(ScenarioError, match=r"^simulation.duration: the run would need about .* GiB"):
        run_sweep(jobs, max_memory_gib=4.0)
    assert main(["sweep", str(tiny), "--set", "simulation.duration=1e9"]) == 2
    assert "--max-memory GIB" in capsys.readouterr().err
    assert len(run_sweep(jobs[:1], max_memory_gib=4.0)) == 1


def test_a_byte_order_mark_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + TINY.encode())
    assert load_job(SweepJob(str(path), (("controller.horizon", 3),), 2)).controller.mpc.horizon == 3


def test_an_unknown_solver_is_refused_before_any_job() -> None:
    with pytest.raises(ValidationError, match="--solver: solver 'bogus': unknown solver"):
        build_jobs("scenarios/swap_planar_8.toml", [0], [], solver="bogus")


def test_a_sweep_over_the_run_limit_is_refused_naming_its_largest_list(tiny: Path) -> None:
    assert len(build_jobs(tiny, list(range(1000)), [("seed", list(range(100)))])) == MAX_RUNS
    with pytest.raises(ValidationError, match=r"^--seeds: the sweep would make 100,100 runs \(1,001 x 100\)"):
        build_jobs(tiny, list(range(1001)), [("seed", list(range(100)))])
    with pytest.raises(ValidationError, match=r"^--set: .* 200,000 runs \(2 x 100,000\), above the limit"):
        build_jobs(tiny, [0, 1], [("controller.horizon", list(range(100_000)))])


def test_a_plant_rate_too_high_fails_before_any_run() -> None:
    quad = str(Path(__file__).resolve().parents[2] / "scenarios" / "swap_spatial_12_quadrotor_wind.toml")
    jobs = build_jobs(quad, None, [("plant.rate", [1e6])])
    with pytest.raises(ScenarioError, match=r"^plant.rate: the plant would take 1.2e\+08 inner steps"):
        run_sweep(jobs, max_work=5e7)


def test_a_run_that_ends_incomplete_is_a_failure_of_its_completion(tiny: Path) -> None:
    """The tiny swap cut to 0.2 s: its drones have not arrived, so the run fails its completion check."""
    record = run_sweep([SweepJob(tiny, (("simulation.duration", 0.2),), None)], workers=1)[0]
    assert record["completion"] < 1.0 and not record["success"]
    assert "completion" in record["failed_checks"]
