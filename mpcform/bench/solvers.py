"""``mpcform bench solvers`` and ``mpcform bench closed-loop``: QP solvers on the planner's own problems.

**Problem benchmark** (conventions of qpbenchmark / mpc_qpbenchmark). Every backend solves every
recorded problem (:mod:`mpcform.bench.problems`) at four accuracy settings: ``default`` (the solver's
own settings) and ``low`` / ``mid`` / ``high`` (``eps_abs`` 1e-3 / 1e-6 / 1e-9, ``eps_rel`` 0,
mapped to each solver's parameters), in two modes: ``cold`` (a fresh setup per problem, no warm
start) and ``warm`` (each scenario's sequence replayed as the planner runs it: set up at its
first problem, then updated, warm-started from the planner's ``x0`` where the backend uses one;
only for backends that are persistent or warm-start). A solve *succeeds* when it is found within
the time limit with primal residual ``<= tol`` and objective gap ``|f - f*| / max(1, |f*|) <=
tol``, ``tol`` = 1e-3 for default and low, 1e-6 for mid, 1e-9 for high; ``f*`` is the same QP
solved by clarabel at 1e-9 (``eps_rel`` 0). Runtimes are wall-clock setup (or update) + solve.
Their shifted geometric mean uses a shift of 1e-4 s (0.1 ms, about the fastest solves here, so
that sub-millisecond noise does not dominate the ratios while a 10x slower solver still scores
about 10x), and counts failures at the time limit (qpbenchmark's rule); medians and p90s are over
successful solves. ``casadi:ipopt`` solves the exact non-convex problem instead (reported apart:
its objective is below the QP's, and the difference is the price of the linearisation).

**Isolation, side by side.** Each solver runs in its own process (``spawn``), all of them alive
at once and asked one solve at a time, slot by slot: every solver solves problem k (of a mode
and setting) before any solves problem k + 1, so a change of the shared machine's load affects
all solvers alike and the ratios are measured side by side. The parent waits for each solve
with a hard limit (3x the time limit, at least the limit + 5 s). A solver that hangs is killed
and that solve recorded as a timeout; one that crashes (a segfault) is recorded as crashed; in
both cases a new process carries on with the next problem. After two consecutive solves over the
time limit (killed, or answering late) the rest of that solver's group (mode, setting) is
recorded as failed without running: problems come in increasing size, and a solve over the time
limit is a failure anyway. A missing or unsupported solver is reported, not run. The benchmark
never aborts for a solver.

**Closed loop.** Each solver drives the same scenarios through ``MPCPlanner(solver=...)`` (in
its own process, with a time limit per run): tracking error, minimum separation along segments,
slack, fallbacks and per-step times of QP steps.

Benchmarks set ``OPENBLAS_NUM_THREADS=1`` and ``OMP_NUM_THREADS=1`` for the processes they start.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import platform
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

from mpcform.bench.problems import (
    DEFAULT_PROBLEMS_DIR,
    DEFAULT_SCENARIOS,
    RecordedQP,
    load_problem,
    problem_files,
)
from mpcform.outputs.tables import Column, markdown_table
from mpcform.solvers.base import QPBackend, SolverOptions
from mpcform.solvers.registry import check_solver_name, make_backend, solver_info, solver_names

SETTINGS: dict[str, float | None] = {"default": None, "low": 1e-3, "mid": 1e-6, "high": 1e-9}
"""Accuracy settings: eps_abs given to the solver (None: the solver's defaults); eps_rel is 0."""
TOLERANCES = {"default": 1e-3, "low": 1e-3, "mid": 1e-6, "high": 1e-9}
"""Validation tolerance per setting, on the primal residual and the relative objective gap."""
MODES = ("cold", "warm")
REFERENCE_SOLVER = "qpsolvers:clarabel"
REFERENCE_EPS = 1e-9
EXACT_SOLVER = "casadi:ipopt"
SHIFT_S = 1e-4
DEFAULT_TIME_LIMIT_S = 1.0
EXACT_TIME_LIMIT_S = 60.0
MAX_CONSECUTIVE_TIMEOUTS = 2
BENCH_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
SOLVER_PACKAGES = (
    "osqp",
    "piqp",
    "qpsolvers",
    "clarabel",
    "daqp",
    "highspy",
    "proxsuite",
    "quadprog",
    "scs",
    "casadi",
)


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


def options_for(eps: float | None, time_limit_s: float) -> SolverOptions:
    """Solver options of an accuracy setting: the solver's defaults (``eps`` None) or ``eps_abs =
    eps, eps_rel = 0``; the time limit goes to solvers that take one."""
    if eps is None:
        return SolverOptions(None, None, None, time_limit_s)
    return SolverOptions(eps, 0.0, None, time_limit_s)


def exact_residual(qp: RecordedQP, x: np.ndarray) -> float:
    """Largest violation of the exact problem: the QP's rows other than the linearised separation
    rows, and the true distance constraints of its context."""
    from mpcform.solvers.exact import exact_separation_residual

    ctx = qp.context
    if ctx is None:
        return math.inf
    keep = np.ones(qp.n_rows, dtype=bool)
    keep[ctx.separation_rows[0] : ctx.separation_rows[1]] = False
    ax = qp.A[keep] @ x
    linear = max(np.max(qp.l[keep] - ax, initial=0.0), np.max(ax - qp.u[keep], initial=0.0))
    return float(max(linear, exact_separation_residual(ctx, x)))


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
) -> list[dict[str, Any]]:
    """Run ``tasks`` in one child process per solver, side by side, with a hard time limit per solve.

    Tasks are taken slot by slot (mode, setting, problem): every solver solves problem k before
    any solves problem k + 1 (in a rotating order), so that a change of the machine's load
    affects all of them alike; each solver's own tasks keep their order (warm sequences). The
    hard limit is ``max(3 time_limit, time_limit + grace_s)``. A timeout or crash is recorded
    for the task it happened in and the solver gets a fresh process for its next task; after
    :data:`MAX_CONSECUTIVE_TIMEOUTS` solves in a row over the time limit (killed, or answering
    late), the rest of that solver's group (mode, setting) is recorded as skipped. Returns one
    result per task, in order; ``worker`` is the processes' entry point.
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


# ---- the problem benchmark ------------------------------------------------------------------
def shifted_geometric_mean(values: Sequence[float], shift: float = SHIFT_S) -> float:
    """``exp(mean(log(v + shift))) - shift`` of nonnegative values."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return math.nan
    return float(np.exp(np.mean(np.log(v + shift))) - shift)


def default_solvers() -> list[str]:
    """Every backend known here except the exact NLP (it is run separately)."""
    return [name for name in solver_names() if name != EXACT_SOLVER]


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


def _gap(objective: float | None, reference: float | None) -> float:
    if objective is None or reference is None:
        return math.nan
    return (objective - reference) / max(1.0, abs(reference))


def succeeded(res: dict[str, Any], reference: float | None, time_limit_s: float) -> bool:
    """Found within the time limit, primal residual and |objective gap| within the setting's tolerance."""
    tol = TOLERANCES[res["setting"]]
    if not res["found"] or res["runtime_s"] > time_limit_s or res["primal_residual"] > tol:
        return False
    return res["solver"] == EXACT_SOLVER or abs(_gap(res["objective"], reference)) <= tol


def summarize(
    results: Sequence[dict[str, Any]], references: Sequence[float | None], time_limit_s: float
) -> list[dict[str, Any]]:
    """One record per (solver, mode, setting): success rate, runtimes, residuals, objective gaps."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    rows: list[dict[str, Any]] = []
    for res in results:
        groups.setdefault((res["solver"], res["mode"], res["setting"]), []).append(res)
    rows = []
    for (solver, mode, setting), group in groups.items():
        ok = [succeeded(r, references[r["index"]], time_limit_s) for r in group]
        found = [r for r in group if r["found"]]
        good = [r for r, s in zip(group, ok, strict=True) if s]
        times = [r["runtime_s"] if r["found"] else time_limit_s for r in group]
        ms = [1e3 * r["runtime_s"] for r in good]
        gaps = [abs(_gap(r["objective"], references[r["index"]])) for r in found]
        statuses = Counter(r["status"] for r in group if not r["found"])
        rows.append(
            {
                "solver": solver,
                "mode": mode,
                "setting": setting,
                "problems": len(group),
                "success_rate": 100.0 * sum(ok) / len(group),
                "shgeom_runtime_ms": 1e3 * shifted_geometric_mean(times),
                "median_runtime_ms": float(np.median(ms)) if ms else None,
                "p90_runtime_ms": float(np.percentile(ms, 90)) if ms else None,
                "primal_residual_max": max((r["primal_residual"] for r in found), default=None),
                "objective_gap_max": max((g for g in gaps if not math.isnan(g)), default=None),
                "found": len(found),
                "failures": dict(statuses.most_common(3)),
            }
        )
    for mode, setting in {(r["mode"], r["setting"]) for r in rows}:
        peers = [r for r in rows if (r["mode"], r["setting"]) == (mode, setting)]
        best = min(r["shgeom_runtime_ms"] for r in peers)
        for r in peers:
            r["shgeom_ratio"] = r["shgeom_runtime_ms"] / best if best > 0 else math.nan
    return rows


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
    progress: Callable[[str], None] | None = None,
) -> SolverBenchmark:
    """Run the problem benchmark (see the module docstring) on the problems in ``problems_dir``."""
    start, load = time.perf_counter(), os.getloadavg()[0]
    paths = [str(p) for p in problem_files(problems_dir)]
    problems = [load_problem(p) for p in paths]
    names = list(default_solvers() if solvers is None else solvers)
    for name in names:
        check_solver_name(name)  # an unknown name is a usage error before anything runs

    def say(text: str) -> None:
        if progress is not None:
            progress(text)

    say(f"reference: {REFERENCE_SOLVER} at {REFERENCE_EPS:g}")
    ref_tasks = [
        Task(i, p, REFERENCE_SOLVER, "high", "cold", True, REFERENCE_EPS, 60.0) for i, p in enumerate(paths)
    ]
    references = [r["objective"] if r["found"] else None for r in run_isolated(ref_tasks)]
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
    say(f"{len(tasks)} solves by {len(names) - len(not_run)} solvers, side by side")
    results = run_isolated(tasks)
    exact_results: list[dict[str, Any]] = []
    if exact and solver_info(EXACT_SOLVER).usable:
        say(f"exact reference: {EXACT_SOLVER}")
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


# ---- report ---------------------------------------------------------------------------------
SUMMARY_COLUMNS: list[Column] = [
    ("solver", "solver", "{}"),
    ("success_rate", "success [%]", "{:.0f}"),
    ("shgeom_runtime_ms", "shgeom [ms]", "{:.3g}"),
    ("shgeom_ratio", "ratio", "{:.1f}"),
    ("median_runtime_ms", "median [ms]", "{:.3g}"),
    ("p90_runtime_ms", "p90 [ms]", "{:.3g}"),
    ("primal_residual_max", "max primal residual", "{:.1e}"),
    ("objective_gap_max", "max objective gap", "{:.1e}"),
    ("failures", "failures", "{}"),
]
EXACT_COLUMNS: list[Column] = [
    ("scenario", "scenario", "{}"),
    ("solved", "solved", "{}"),
    ("median_ms", "median [ms]", "{:.3g}"),
    ("residual", "exact residual (max)", "{:.1e}"),
    ("gap_median", "gap median", "{:.2e}"),
    ("gap_min", "gap min", "{:.2e}"),
]
CLOSED_LOOP_COLUMNS: list[Column] = [
    ("scenario", "scenario", "{}"),
    ("solver", "solver", "{}"),
    ("final_tracking_error_m", "final error [m]", "{:.2e}"),
    ("max_tracking_error_m", "max error [m]", "{:.3f}"),
    ("min_separation_m", "min separation [m]", "{:.4f}"),
    ("separation_violations", "violations", "{}"),
    ("max_slack_m", "max slack [m]", "{:.1e}"),
    ("qp_solves", "QP steps", "{}"),
    ("fallbacks", "fallbacks", "{}"),
    ("qp_step_median_ms", "QP step median [ms]", "{:.3g}"),
    ("qp_step_p90_ms", "p90 [ms]", "{:.3g}"),
    ("wall_s", "wall [s]", "{:.1f}"),
]


def _failures(counts: dict[str, int]) -> str:
    return "; ".join(f"{k} ({v})" for k, v in counts.items())[:90] or "-"


def _versions() -> str:
    found = []
    for pkg in SOLVER_PACKAGES:
        try:
            found.append(f"{pkg} {metadata.version(pkg)}")
        except metadata.PackageNotFoundError:
            continue
    return ", ".join(found)


def _span(values: Sequence[int]) -> str:
    return f"{min(values)}" if min(values) == max(values) else f"{min(values)}-{max(values)}"


def _problem_lines(problems: Sequence[RecordedQP]) -> list[str]:
    by: dict[str, list[RecordedQP]] = {}
    for qp in problems:
        by.setdefault(str(qp.meta["scenario"]), []).append(qp)
    lines = []
    for name, qps in by.items():
        nv = [qp.n_var for qp in qps]
        nr = [qp.n_rows for qp in qps]
        steps = [int(qp.meta["step"]) for qp in qps]
        drones = sorted({int(qp.meta["n"]) for qp in qps})
        lines.append(
            f"  - `{name}`: {len(qps)} QPs (steps {min(steps)}-{max(steps)}), {_span(drones)} drones in the "
            f"QP, d = {qps[0].meta['dim']}, {_span(nv)} variables, {_span(nr)} rows, "
            f"nnz(A) up to {max(qp.A.nnz for qp in qps)}"
        )
    return lines


def markdown_report(bench: SolverBenchmark) -> str:
    """The markdown report of a problem benchmark."""
    refs_ok = sum(r is not None for r in bench.references)
    tl = bench.time_limit_s
    out = [
        "# Solver benchmark on the planner's QPs",
        "",
        f"- Problems: {len(bench.problems)} recorded QPs:",
        *_problem_lines(bench.problems),
        f"- Reference objective f*: {REFERENCE_SOLVER} at eps_abs {REFERENCE_EPS:g} (eps_rel 0), cold: "
        f"{refs_ok}/{len(bench.references)} solved.",
        "- Settings: `default` = each solver's own settings; `low` / `mid` / `high` = eps_abs 1e-3 / 1e-6 / "
        "1e-9 with eps_rel 0, mapped to each solver's parameters.",
        "- Success: found within the time limit, primal residual <= tol and objective gap "
        "|f - f*| / max(1, |f*|) <= tol, with tol = 1e-3 (default, low), 1e-6 (mid), 1e-9 (high).",
        f"- Runtime: wall-clock setup + solve (cold) or update + solve (warm), time limit {tl:g} s. "
        f"`shgeom` = shifted geometric mean with shift {SHIFT_S * 1e3:g} ms, failures counted at the time "
        "limit; `ratio` = shgeom / best shgeom of the table; median and p90 over successful solves.",
        "- Modes: `cold` = fresh setup, no warm start; `warm` = each scenario's sequence replayed as the "
        "planner runs it (set up once, then updated; warm-started from the planner's x0 where the backend "
        "uses one), only for backends that are persistent or warm-start.",
        f"- Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
        f"{platform.python_version()}, OPENBLAS_NUM_THREADS=1; solvers interleaved problem by problem, one "
        f"solve at a time; {_versions()}.",
        f"- Wall time of the benchmark: {bench.wall_s:.0f} s; load average (1 min) {bench.load[0]:.1f} at "
        f"the start, {bench.load[1]:.1f} at the end (the machine is shared: compare ratios within one run).",
        "",
    ]
    for mode in bench.modes:
        out += [f"## {'Cold start' if mode == 'cold' else 'Warm-start replay'}", ""]
        for setting in bench.settings:
            rows = [r for r in bench.rows if (r["mode"], r["setting"]) == (mode, setting)]
            if not rows:
                continue
            rows.sort(key=lambda r: (-r["success_rate"], r["shgeom_runtime_ms"]))
            table = markdown_table(rows, SUMMARY_COLUMNS, {"failures": _failures})
            out += [f"### {setting} (tol {TOLERANCES[setting]:g})", "", table, ""]
    if bench.exact:
        out += _exact_section(bench)
    if bench.not_run:
        rows = [{**r, "installed": "yes" if r["installed"] else "no"} for r in bench.not_run]
        columns = [("solver", "solver", "{}"), ("installed", "installed", "{}"), ("note", "why", "{}")]
        out += ["## Not run", "", markdown_table(rows, columns), ""]
    return "\n".join(out)


def _exact_section(bench: SolverBenchmark) -> list[str]:
    by: dict[str, list[tuple[RecordedQP, dict[str, Any], float | None]]] = {}
    for qp, res, ref in zip(bench.problems, bench.exact, bench.references, strict=True):
        by.setdefault(str(qp.meta["scenario"]), []).append((qp, res, ref))
    out = [
        f"## Exact non-convex reference ({EXACT_SOLVER})",
        "",
        "ipopt (tol 1e-6) on the exact problem: the QP's cost and rows with its linearised separation rows "
        "replaced by the true distance constraints at every step, warm-started from the planner's x0 "
        f"(time limit {EXACT_TIME_LIMIT_S:g} s). The gap (f_exact - f_QP*) / max(1, |f_QP*|) is <= 0 (the "
        "linearisation is conservative); its size is the price of convexifying the separation.",
        "",
    ]
    table = []
    for name, items in by.items():
        solved = [(r, ref) for _, r, ref in items if r["found"]]
        gaps = [_gap(r["objective"], ref) for r, ref in solved if ref is not None]
        ms = [1e3 * r["runtime_s"] for r, _ in solved]
        table.append(
            {
                "scenario": name,
                "solved": f"{len(solved)}/{len(items)}",
                "median_ms": float(np.median(ms)) if ms else None,
                "residual": max((r["primal_residual"] for r, _ in solved), default=None),
                "gap_median": float(np.median(gaps)) if gaps else None,
                "gap_min": min(gaps, default=None),
            }
        )
    out.append(markdown_table(table, EXACT_COLUMNS))
    out.append("")
    return out


def records(bench: SolverBenchmark) -> list[dict[str, Any]]:
    """The rows of the report as JSON records (``--json``)."""
    return [*bench.rows, *({"mode": None, "setting": None, **r} for r in bench.not_run)]


# ---- closed loop ----------------------------------------------------------------------------
def _closed_loop_worker(conn: Connection, scenario: str, solver: str, duration_s: float | None) -> None:
    import dataclasses

    from mpcform.scenario.spec import load_scenario, run_scenario

    try:
        sc = load_scenario(scenario)
        if duration_s is not None:
            sc = dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation, duration_s=duration_s))
        start = time.perf_counter()
        run = run_scenario(sc, controller="mpc", solver=solver)
        conn.send(
            {
                "ok": True,
                "metrics": run.summary["metrics"],
                "wall_s": time.perf_counter() - start,
                "steps": run.summary["steps"],
                "scenario": sc.name,
            }
        )
    except Exception as exc:  # noqa: BLE001 - reported as this run's failure
        conn.send({"ok": False, "status": f"{type(exc).__name__}: {exc}"[:300]})
    conn.close()


def run_closed_loop(
    scenarios: Sequence[str | Path] = DEFAULT_SCENARIOS[:2],
    solvers: Sequence[str] | None = None,
    timeout_s: float = 600.0,
    duration_s: float | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Each solver drives each scenario (controller ``mpc``) in its own process; one record per run."""
    infos = [solver_info(n) for n in (default_solvers() if solvers is None else solvers)]  # unknown: raises
    ctx = mp.get_context("spawn")
    rows = []
    os.environ.update(BENCH_ENV)
    for scenario in scenarios:
        for info in infos:
            name = info.name
            if not info.usable:  # missing or unsupported: reported, not run
                rows.append(_closed_loop_row(Path(scenario).stem, name, {"ok": False, "status": info.note}))
                continue
            if progress is not None:
                progress(f"{Path(scenario).stem}: {name}")
            receiver, sender = ctx.Pipe(duplex=False)
            proc = ctx.Process(
                target=_closed_loop_worker, args=(sender, str(scenario), name, duration_s), daemon=True
            )
            proc.start()
            sender.close()
            try:
                out = (
                    receiver.recv()
                    if receiver.poll(timeout_s)
                    else {"ok": False, "status": f"timeout ({timeout_s:g} s)"}
                )
            except EOFError:
                proc.join(1.0)
                out = {"ok": False, "status": f"crashed (exit code {proc.exitcode})"}
            if proc.is_alive():
                proc.kill()
            proc.join()
            receiver.close()
            rows.append(_closed_loop_row(Path(scenario).stem, name, out))
    return rows


def _closed_loop_row(scenario: str, solver: str, out: dict[str, Any]) -> dict[str, Any]:
    if not out["ok"]:
        return {"scenario": scenario, "solver": solver, "ok": False, "status": out["status"]}
    m = out["metrics"]
    qp_ms = m["step_time_ms"].get("qp", {})
    return {
        "scenario": scenario,
        "solver": solver,
        "ok": True,
        "status": "ok",
        "steps": out["steps"],
        "final_tracking_error_m": m["final_tracking_error"],
        "max_tracking_error_m": m["max_tracking_error"],
        "min_separation_m": m["min_separation_segments"],
        "separation_violations": m["separation_violations"],
        "max_slack_m": m["max_slack"],
        "qp_solves": m["qp_solves"],
        "fallbacks": m["solver_failures"],
        "qp_step_median_ms": qp_ms.get("median"),
        "qp_step_p90_ms": qp_ms.get("p90"),
        "wall_s": out["wall_s"],
    }


def _error_cell(value: Any) -> str:
    return value if isinstance(value, str) else "-" if value is None else f"{value:.2e}"


def closed_loop_markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The markdown table of a closed-loop benchmark."""
    out = [
        "# Closed-loop solver benchmark",
        "",
        "Each solver drives the scenario through `MPCPlanner(solver=...)` (the scenario's settings, one "
        "process per run). Tracking errors are max over drones of |p_i - p*_i| [m]; min separation is "
        "along the straight segments [m]; QP-step times exclude fast-path steps.",
        "",
    ]
    table = [r if r["ok"] else {**r, "final_tracking_error_m": f"failed: {r['status'][:100]}"} for r in rows]
    out.append(markdown_table(table, CLOSED_LOOP_COLUMNS, {"final_tracking_error_m": _error_cell}))
    return "\n".join(out) + "\n"
