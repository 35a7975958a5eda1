"""Isolated solves of ``mpcform bench solvers``: each solver in its own process, side by side.

Each solver runs in its own process (``spawn``), all of them alive at once and asked one solve at
a time, slot by slot: every solver solves problem k (of a mode and setting) before any solves
problem k + 1, so a change of the shared machine's load affects all solvers alike and the ratios
are measured side by side. The parent waits for each solve with a hard limit (3x the time limit,
at least the limit + 5 s). A solver that hangs is killed and that solve recorded as a timeout; one
that crashes (a segfault) is recorded as crashed; in both cases a new process carries on with the
next problem. After two consecutive solves over the time limit (killed, or answering late) the
rest of that solver's group (mode, setting) is recorded as failed without running: problems come
in increasing size, and a solve over the time limit is a failure anyway. The benchmark never
aborts for a solver.

Modes: ``cold`` (a fresh setup per problem, no warm start) and ``warm`` (each scenario's sequence
replayed as the planner runs it: set up at its first problem, then updated, warm-started from the
planner's ``x0`` where the backend uses one). Runtimes are wall-clock setup (or update) + solve.

Benchmarks set ``OPENBLAS_NUM_THREADS=1`` and ``OMP_NUM_THREADS=1`` for the processes they start.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from mpcform.bench.accuracy import EXACT_SOLVER, SETTINGS, exact_residual, options_for
from mpcform.bench.problems import RecordedQP, load_problem
from mpcform.solvers.base import QPBackend
from mpcform.solvers.registry import make_backend

MODES = ("cold", "warm")
"""Fresh setup per problem, or each scenario's sequence replayed as the planner runs it."""
MAX_CONSECUTIVE_TIMEOUTS = 2
BENCH_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
"""Set for the processes a benchmark starts."""


@dataclass(frozen=True)
class Task:
    """One solve: problem ``index`` (file ``path``) by ``solver`` at ``setting`` in ``mode``;
    ``first`` marks the start of a warm replay sequence."""

    index: int
    path: str
    solver: str
    setting: str
    mode: str
    first: bool
    eps: float | None
    time_limit_s: float

    @property
    def group(self) -> tuple[str, str, str]:
        return self.solver, self.mode, self.setting


def _result(task: Task, **fields: Any) -> dict[str, Any]:
    return {"index": task.index, "solver": task.solver, "setting": task.setting, "mode": task.mode, **fields}


def _failure(task: Task, status: str, runtime_s: float) -> dict[str, Any]:
    return _result(
        task, found=False, status=status, runtime_s=runtime_s, objective=None, primal_residual=None
    )


class _Runner:
    """Runs tasks in order in one process, keeping the warm backend of the current sequence."""

    def __init__(self) -> None:
        self._problems: dict[str, RecordedQP] = {}
        self._backend: QPBackend | None = None
        self._key: tuple[str, str, str] | None = None
        self._pattern: tuple[bytes, bytes] | None = None

    def problem(self, path: str) -> RecordedQP:
        if path not in self._problems:
            self._problems[path] = load_problem(path)
        return self._problems[path]

    def run(self, task: Task) -> dict[str, Any]:
        qp = self.problem(task.path)
        options = options_for(task.eps, task.time_limit_s)
        pattern = (qp.A.indptr.tobytes(), qp.A.indices.tobytes())
        start = time.perf_counter()
        try:
            warm = task.mode == "warm"
            fresh = not warm or task.first or self._key != task.group
            backend = self._backend
            if fresh or backend is None:
                backend = self._backend = make_backend(task.solver, options)
            start = time.perf_counter()
            if fresh or pattern != self._pattern:
                backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
            else:
                backend.update(qp.q, qp.l, qp.u, qp.A.data)
            if backend.needs_context and qp.context is not None:
                backend.set_context(qp.context)
            sol = backend.solve(qp.x0 if warm and backend.warm_starts else None)
            runtime = time.perf_counter() - start
        except Exception as exc:  # noqa: BLE001 - recorded as this solve's failure, never aborts the benchmark
            self._backend = None
            return _failure(task, f"error: {type(exc).__name__}: {exc}"[:300], time.perf_counter() - start)
        self._key, self._pattern = task.group, pattern
        if not sol.success or sol.x is None:
            return _failure(task, sol.status, runtime)
        residual = exact_residual(qp, sol.x) if task.solver == EXACT_SOLVER else qp.primal_residual(sol.x)
        return _result(
            task,
            found=True,
            status=sol.status,
            runtime_s=runtime,
            objective=qp.objective(sol.x),
            primal_residual=residual,
        )


def _worker(conn: Connection) -> None:
    """Process entry point: say ready, then answer each task sent (None ends)."""
    runner = _Runner()
    conn.send(("ready", ""))
    while (task := conn.recv()) is not None:
        conn.send(("result", runner.run(task)))
    conn.close()


class _Child:
    """One solver's process, asked one task at a time."""

    def __init__(self, ctx: Any, worker: Callable[[Connection], None], startup_s: float = 120.0) -> None:
        self.conn, child_end = ctx.Pipe()
        self.proc = ctx.Process(target=worker, args=(child_end,), daemon=True)
        self.proc.start()
        child_end.close()
        if not self.conn.poll(startup_s):
            self.close()
            raise TimeoutError(f"the solver's process did not start within {startup_s:g} s")
        self.conn.recv()

    def ask(self, task: Task, hard_s: float) -> dict[str, Any] | str:
        """The task's result, or why there is none (a timeout or a crash)."""
        try:
            self.conn.send(task)
            if not self.conn.poll(hard_s):
                return f"timeout (killed after {hard_s:g} s)"
            return self.conn.recv()[1]
        except (EOFError, OSError):
            self.proc.join(1.0)
            return f"crashed (exit code {self.proc.exitcode})"

    def close(self) -> None:
        if self.proc.is_alive():
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.proc.join(0.5)
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join()
        self.conn.close()


def _slot(task: Task) -> tuple[int, int, int]:
    modes, settings = list(MODES), list(SETTINGS)
    return (
        modes.index(task.mode) if task.mode in modes else 0,
        settings.index(task.setting) if task.setting in settings else 0,
        task.index,
    )


def run_isolated(
    tasks: Sequence[Task],
    progress: Callable[[dict[str, Any]], None] | None = None,
    grace_s: float = 5.0,
    worker: Callable[[Connection], None] = _worker,
    starting: Callable[[Task], None] | None = None,
) -> list[dict[str, Any]]:
    """Run ``tasks`` in one child process per solver, side by side, with a hard time limit per solve.

    Tasks are taken slot by slot (mode, setting, problem): every solver solves problem k before
    any solves problem k + 1 (in a rotating order), so that a change of the machine's load
    affects all of them alike; each solver's own tasks keep their order (warm sequences). The
    hard limit is ``max(3 time_limit, time_limit + grace_s)``. A timeout or crash is recorded
    for the task it happened in and the solver gets a fresh process for its next task; after
    :data:`MAX_CONSECUTIVE_TIMEOUTS` solves in a row over the time limit (killed, or answering
    late), the rest of that solver's group (mode, setting) is recorded as skipped. Returns one
    result per task, in order; ``worker`` is the processes' entry point; ``starting(task)`` is
    called before each task runs (or is skipped), ``progress(result)`` after.
    """
    ctx = mp.get_context("spawn")
    slots: dict[tuple[int, int, int], list[int]] = {}
    for i, task in enumerate(tasks):
        slots.setdefault(_slot(task), []).append(i)
    results: dict[int, dict[str, Any]] = {}
    late: Counter[tuple[str, str, str]] = Counter()
    abandoned: set[tuple[str, str, str]] = set()
    children: dict[str, _Child] = {}
    env_before = {k: os.environ.get(k) for k in BENCH_ENV}
    os.environ.update(BENCH_ENV)
    try:
        for n, key in enumerate(sorted(slots)):
            ids = slots[key]
            for i in ids[n % len(ids) :] + ids[: n % len(ids)]:
                task = tasks[i]
                if starting is not None:
                    starting(task)
                if task.group in abandoned:
                    why = f"skipped after {MAX_CONSECUTIVE_TIMEOUTS} solves over the time limit"
                    results[i] = _failure(task, why, 0.0)
                    continue
                hard = max(3.0 * task.time_limit_s, task.time_limit_s + grace_s)
                try:
                    child = children.get(task.solver) or children.setdefault(task.solver, _Child(ctx, worker))
                    out = child.ask(task, hard)
                except TimeoutError as exc:
                    out = str(exc)
                if isinstance(out, str):  # no answer: a fresh process for this solver's next task
                    results[i] = _failure(task, out, hard if out.startswith("timeout") else 0.0)
                    if task.solver in children:
                        children.pop(task.solver).close()
                else:
                    results[i] = out
                late[task.group] = late[task.group] + 1 if results[i]["runtime_s"] > task.time_limit_s else 0
                if late[task.group] >= MAX_CONSECUTIVE_TIMEOUTS:
                    abandoned.add(task.group)
                if progress is not None:
                    progress(results[i])
    finally:
        for child in children.values():
            child.close()
        for k, v in env_before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return [results[i] for i in range(len(tasks))]
