"""``mpcform bench solvers``: every QP solver on the planner's own recorded problems.

Conventions of qpbenchmark / mpc_qpbenchmark. Every backend solves every recorded problem
(:mod:`mpcform.bench.problems`) at the four accuracy settings of :mod:`mpcform.bench.accuracy`,
in the ``cold`` and ``warm`` modes of :mod:`mpcform.bench.worker` (``warm`` only for backends that
are persistent or warm-start), each solver in its own process with a time limit per solve. The
reference objectives ``f*`` come first (clarabel at 1e-9), then the solvers side by side, then
``casadi:ipopt`` on the exact non-convex problems (reported apart). A missing or unsupported
solver is reported, not run. The report is :mod:`mpcform.bench.report`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpcform.bench.accuracy import (
    EXACT_SOLVER,
    REFERENCE_EPS,
    REFERENCE_SOLVER,
    SETTINGS,
    default_solvers,
    summarize,
)
from mpcform.bench.problems import DEFAULT_PROBLEMS_DIR, RecordedQP, load_problem, problem_files
from mpcform.bench.worker import MODES, Task, run_isolated
from mpcform.solvers.registry import check_solver_name, solver_info

DEFAULT_TIME_LIMIT_S = 1.0
EXACT_TIME_LIMIT_S = 60.0


def benchmark_tasks(
    paths: Sequence[str], solver: str, settings: Sequence[str], modes: Sequence[str], time_limit_s: float
) -> list[Task]:
    """The tasks of one solver: for each mode and setting, every problem in order."""
    scenarios = [Path(p).parent.name for p in paths]
    tasks = []
    for mode in modes:
        for setting in settings:
            for i, path in enumerate(paths):
                first = i == 0 or scenarios[i] != scenarios[i - 1]
                tasks.append(Task(i, path, solver, setting, mode, first, SETTINGS[setting], time_limit_s))
    return tasks


@dataclass
class SolverBenchmark:
    """Everything ``mpcform bench solvers`` reports."""

    problems: list[RecordedQP]
    rows: list[dict[str, Any]]
    references: list[float | None]
    exact: list[dict[str, Any]]
    not_run: list[dict[str, Any]]
    settings: list[str]
    modes: list[str]
    time_limit_s: float
    wall_s: float
    load: tuple[float, float]


def run_solver_benchmark(
    problems_dir: str | Path = DEFAULT_PROBLEMS_DIR,
    solvers: Sequence[str] | None = None,
    settings: Sequence[str] = tuple(SETTINGS),
    modes: Sequence[str] = MODES,
    time_limit_s: float = DEFAULT_TIME_LIMIT_S,
    exact: bool = True,
    progress: Callable[[str, int, int], None] | None = None,
) -> SolverBenchmark:
    """Run the problem benchmark (see the module docstring) on the problems in ``problems_dir``.
    ``progress(label, i, n)`` is called as stage ``i`` of ``n`` starts: the reference, each (mode,
    setting) of the solvers side by side, the exact reference."""
    start, load = time.perf_counter(), os.getloadavg()[0]
    paths = [str(p) for p in problem_files(problems_dir)]
    problems = [load_problem(p) for p in paths]
    names = list(default_solvers() if solvers is None else solvers)
    for name in names:
        check_solver_name(name)  # an unknown name is a usage error before anything runs
    tasks: list[Task] = []
    not_run: list[dict[str, Any]] = []
    for name in names:
        info = solver_info(name)
        if not info.usable:
            not_run.append(
                {
                    "solver": name,
                    "installed": info.installed,
                    "supported": info.installed,
                    "success_rate": 0.0,
                    "note": info.note,
                }
            )
            continue
        solver_modes = [m for m in modes if m == "cold" or info.warm_start or info.persistent]
        tasks += benchmark_tasks(paths, name, settings, solver_modes, time_limit_s)
    exact = exact and solver_info(EXACT_SOLVER).usable
    groups: dict[tuple[str, str], list[str]] = {}
    for task in tasks:
        names_in = groups.setdefault((task.mode, task.setting), [])
        if task.solver not in names_in:
            names_in.append(task.solver)
    stages = 1 + len(groups) + int(exact)
    on = f"on {len(paths)} problems"

    def say(label: str, i: int) -> None:
        if progress is not None:
            progress(label, i, stages)

    begun: list[tuple[str, str]] = []  # the (mode, setting) groups started, in the order they run

    def starting(task: Task) -> None:
        key = (task.mode, task.setting)
        if key not in begun:
            begun.append(key)
            say(f"{task.mode} {task.setting}: {', '.join(groups[key])} side by side {on}", 1 + len(begun))

    say(f"reference {REFERENCE_SOLVER} at {REFERENCE_EPS:g} {on}", 1)
    ref_tasks = [
        Task(i, p, REFERENCE_SOLVER, "high", "cold", True, REFERENCE_EPS, 60.0) for i, p in enumerate(paths)
    ]
    references = [r["objective"] if r["found"] else None for r in run_isolated(ref_tasks)]
    results = run_isolated(tasks, starting=starting)
    exact_results: list[dict[str, Any]] = []
    if exact:
        say(f"exact reference {EXACT_SOLVER} {on}", stages)
        tasks = [
            Task(i, p, EXACT_SOLVER, "mid", "warm", True, 1e-6, EXACT_TIME_LIMIT_S)
            for i, p in enumerate(paths)
        ]
        exact_results = run_isolated(tasks)
    rows = summarize(results, references, time_limit_s)
    return SolverBenchmark(
        problems,
        rows,
        references,
        exact_results,
        not_run,
        list(settings),
        list(modes),
        time_limit_s,
        time.perf_counter() - start,
        (load, os.getloadavg()[0]),
    )
