"""Isolated solves: hanging, crashing and missing solvers are recorded, solvers run side by side."""

from __future__ import annotations

import os
import time
from multiprocessing.connection import Connection
from pathlib import Path

from mpcform.bench.problems import problem_files
from mpcform.bench.worker import Task, run_isolated

ROOT = Path(__file__).resolve().parents[2]


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
