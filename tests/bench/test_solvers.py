"""The solver benchmark: statistics, success rule, isolation of hanging/crashing/missing solvers,
and the ``mpcform bench solvers`` / ``closed-loop`` commands on a tiny subset."""

from __future__ import annotations

import json
import os
import shutil
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import pytest

from mpcform.bench import solvers as bs
from mpcform.bench.problems import problem_files
from mpcform.bench.solvers import Task, run_isolated, shifted_geometric_mean, succeeded, summarize
from mpcform.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def test_shifted_geometric_mean() -> None:
    assert shifted_geometric_mean([2e-3] * 4) == pytest.approx(2e-3)
    assert shifted_geometric_mean([0.0, 1e-4], shift=1e-4) == pytest.approx((1e-4 * 2e-4) ** 0.5 - 1e-4)
    # the shift damps the tiny outliers: 1 us and 1 ms average to about 0.3 ms, not 32 us
    assert 2e-4 < shifted_geometric_mean([1e-6, 1e-3]) < 4e-4


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
    assert succeeded(_res(solver=bs.EXACT_SOLVER, objective=-101.0), -100.0, 1.0)  # exact: gap not judged


def test_summary_counts_failures_at_the_time_limit() -> None:
    results = [_res(index=0), _res(index=1, found=False, status="max iter", runtime_s=0.5)]
    (row,) = summarize(results, [-100.0, -100.0], 1.0)
    assert row["success_rate"] == 50.0 and row["failures"] == {"max iter": 1}
    assert row["shgeom_runtime_ms"] == pytest.approx(1e3 * shifted_geometric_mean([0.01, 1.0]))
    assert row["median_runtime_ms"] == pytest.approx(10.0) and row["shgeom_ratio"] == 1.0


def _send(conn: Connection, task: Task, **extra: object) -> None:
    """A successful result for ``task`` (plus ``extra`` fields)."""
    conn.send(
        (
            "result",
            {
                "index": task.index,
                "solver": task.solver,
                "setting": task.setting,
                "mode": task.mode,
                "found": True,
                "status": "ok",
                "runtime_s": 1e-3,
                "objective": 0.0,
                "primal_residual": 0.0,
                **extra,
            },
        )
    )


def _flaky_worker(conn: Connection) -> None:
    """Hangs on problem 1, crashes on problem 2, answers the others."""
    conn.send(("ready", ""))
    while (task := conn.recv()) is not None:
        if task.index == 1:
            time.sleep(60)
        if task.index == 2:
            os._exit(3)
        _send(conn, task)


def _stuck_worker(conn: Connection) -> None:
    """Hangs on every problem but the first."""
    conn.send(("ready", ""))
    while (task := conn.recv()) is not None:
        if task.index > 0:
            time.sleep(60)
        _send(conn, task)


def _tasks(n: int, solver: str = "fake") -> list[Task]:
    return [Task(i, "unused", solver, "mid", "cold", i == 0, 1e-6, 0.1) for i in range(n)]


def test_a_hanging_or_crashing_solver_is_recorded_and_the_run_goes_on() -> None:
    results = run_isolated(_tasks(5), grace_s=0.5, worker=_flaky_worker)
    assert [r["index"] for r in results] == [0, 1, 2, 3, 4]
    assert [r["found"] for r in results] == [True, False, False, True, True]
    assert results[1]["status"].startswith("timeout") and results[2]["status"] == "crashed (exit code 3)"


def test_repeated_timeouts_skip_the_rest_of_the_group() -> None:
    results = run_isolated(_tasks(5), grace_s=0.5, worker=_stuck_worker)
    assert [r["found"] for r in results] == [True, False, False, False, False]
    assert [r["status"].split()[0] for r in results[1:]] == ["timeout", "timeout", "skipped", "skipped"]


def _order_worker(conn: Connection) -> None:
    """Answers at once, with the time it was asked (to check the interleaving)."""
    conn.send(("ready", ""))
    while (task := conn.recv()) is not None:
        _send(conn, task, at=time.perf_counter())


def test_solvers_run_side_by_side_problem_by_problem() -> None:
    tasks = _tasks(3, "a") + _tasks(3, "b")
    results = run_isolated(tasks, worker=_order_worker)
    order = sorted(results, key=lambda r: r["at"])
    assert [r["index"] for r in order] == [0, 0, 1, 1, 2, 2]  # both solvers solve k before k + 1
    assert [r["solver"] for r in results] == ["a"] * 3 + ["b"] * 3  # results in the tasks' order


def test_a_missing_solver_is_a_failure_not_an_exception() -> None:
    path = str(problem_files(ROOT / "problems")[0])
    tasks = [Task(0, path, "qpsolvers:gurobi", "default", "cold", True, None, 1.0)]
    (res,) = run_isolated(tasks)
    assert not res["found"] and "SolverError" in res["status"]


@pytest.fixture(scope="module")
def tiny_problems(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two consecutive small problems (8 planar drones)."""
    out = tmp_path_factory.mktemp("problems")
    for f in problem_files(ROOT / "problems")[:2]:
        (out / f.parent.name).mkdir(exist_ok=True)
        shutil.copy(f, out / f.parent.name / f.name)
    return out


def test_bench_solvers_cli(tiny_problems: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    json_path, report = tmp_path / "rows.json", tmp_path / "report.md"
    argv = [
        "bench",
        "solvers",
        "--problems",
        str(tiny_problems),
        "--solvers",
        "piqp",
        "qpsolvers:quadprog",
        "--settings",
        "default",
        "high",
        "--no-exact",
        "--json",
        str(json_path),
        "--report",
        str(report),
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "## Cold start" in out and "## Warm-start replay" in out and "| piqp | 100 |" in out
    assert report.read_text().strip() == out.strip()
    rows = json.loads(json_path.read_text())
    piqp = [r for r in rows if r["solver"] == "piqp"]
    assert {(r["mode"], r["setting"]) for r in piqp} == {
        (m, s) for m in bs.MODES for s in ("default", "high")
    }
    assert all(r["success_rate"] == 100.0 and r["problems"] == 2 for r in piqp)
    (quadprog,) = [r for r in rows if r["solver"] == "qpsolvers:quadprog"]
    assert quadprog["success_rate"] == 0.0 and "positive-definite" in quadprog["note"]


def test_bench_solvers_rejects_an_unknown_solver(
    tiny_problems: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bench", "solvers", "--problems", str(tiny_problems), "--solvers", "nope"]) == 2
    assert "unknown solver" in capsys.readouterr().err


def test_bench_closed_loop_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    json_path = tmp_path / "rows.json"
    scenario = str(ROOT / "scenarios" / "swap_planar_8.toml")
    argv = [
        "bench",
        "closed-loop",
        scenario,
        "--solvers",
        "piqp",
        "osqp",
        "qpsolvers:quadprog",
        "--duration",
        "0.5",
        "--json",
        str(json_path),
    ]
    assert main(argv) == 0
    assert "| swap_planar_8 | piqp |" in capsys.readouterr().out
    rows = json.loads(json_path.read_text())
    assert [r["solver"] for r in rows] == ["piqp", "osqp", "qpsolvers:quadprog"]
    assert all(r["ok"] and r["steps"] == 5 and r["separation_violations"] == 0 for r in rows[:2])
    assert not rows[2]["ok"] and "positive-definite" in rows[2]["status"]  # reported, not run
