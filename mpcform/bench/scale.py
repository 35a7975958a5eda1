"""``mpcform bench scale``: planner step time and peak memory from tens to a thousand drones.

The scenarios (``formation`` and ``crossing``, at constant density) are those of
:mod:`mpcform.bench.scale_cases`, horizon 10 by default. Each case runs a fixed number of
closed-loop steps with exact execution; only :meth:`MPCPlanner.step` is timed (wall clock, and
the process's CPU time: on a loaded machine the CPU time is the steadier figure), and within it
the solver's calls (each step's ``solve_time_s``, wall): the bare solver floor, against which the
median step of those that called the solver is set (``solver_ratio``). A step longer than
dt = 0.1 s (wall) is a deadline miss. With ``profile_path`` every case is run again under
:mod:`cProfile` (:mod:`mpcform.bench.profiling`). Modes
(:func:`mpcform.mpc.settings.mode_settings`): ``decoupled`` (``coupling="decoupled"``, grouping,
each conflicted drone's QP solved by DAQP), ``decoupled-sparse`` (the same as one sparse QP with
the ``--solver``), ``joint`` (joint rows, conflict grouping) and ``monolithic`` (``grouping=False``,
``coupling="joint"``: the one joint QP over every drone whenever a solve is needed). The
monolithic cases run under a wall-clock budget: a case over budget stops early (its row says
so) and larger n of that scenario are skipped.

Memory: by default every case runs in a fresh spawned process, and ``rss_peak_mib`` is that
process's ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` after the run (everything: interpreter,
numpy, scipy, the solver's C/C++ allocations), ``rss_delta_mib`` its growth over the planning
steps. ``--tracemalloc`` reruns each case under :mod:`tracemalloc` for the peak of Python and
numpy allocations during the planning steps (solver-internal allocations are not traced).

Set ``OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1`` on the command line; the spawned case processes
get them anyway (see :mod:`mpcform.run.parallel`).
"""

from __future__ import annotations

import cProfile
import math
import resource
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any, cast

import numpy as np

from mpcform._validate import Array
from mpcform.bench.profiling import top_functions, write_profiles
from mpcform.bench.scale_cases import DT_S, LIMITS, SCENARIOS, make_case
from mpcform.bench.stats import median_p90, p50_p99_max, solver_floor
from mpcform.errors import ValidationError
from mpcform.formation.geometry import min_segment_distance
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings, mode_settings
from mpcform.mpc.step_info import MPCStepInfo
from mpcform.run.parallel import blas_threads, process_pool
from mpcform.solvers.registry import DEFAULT_SOLVER

DEFAULT_N = (10, 30, 100, 300, 1000)


def _solver(settings: MPCSettings, solver: str) -> str | None:
    """The backend for a mode: the per-drone decoupled mode takes no sparse solver (None)."""
    return None if settings.solves_per_drone else solver


def _maxrss_mib() -> float:
    """Peak resident set size of this process [MiB] (ru_maxrss is KiB on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


def _closed_loop(
    planner: MPCPlanner, p: Array, steps: int, budget_s: float, profiler: cProfile.Profile | None = None
) -> dict[str, Any]:
    """Run ``steps`` steps (or until ``budget_s`` of planning time); time every planner call (wall
    clock, and the process's CPU time) and the solver's calls within it (``floor``: each step's
    wall time and ``solve_time_s`` [ms]). ``profiler`` is enabled around the planner calls (a
    profiled run's times are not meant to be reported)."""
    planner.reset(0.0, p)
    times: dict[str, list[float]] = {"qp": [], "fast_path": [], "fallback": []}
    cpu: dict[str, list[float]] = {"qp": [], "fast_path": [], "fallback": []}
    floor: tuple[list[float], list[float]] = ([], [])
    qp_drones: list[int] = []
    min_seg, max_slack, spent = float("inf"), 0.0, 0.0
    done = 0
    for j in range(steps):
        if profiler is not None:
            profiler.enable()
        start, start_cpu = time.perf_counter(), time.process_time()
        out = planner.step(DT_S * j, p)
        elapsed, elapsed_cpu = time.perf_counter() - start, time.process_time() - start_cpu
        if profiler is not None:
            profiler.disable()
        spent += elapsed
        times[out.info.mode].append(1e3 * elapsed)
        cpu[out.info.mode].append(1e3 * elapsed_cpu)
        info = cast(MPCStepInfo, out.info)
        floor[0].append(1e3 * elapsed)
        floor[1].append(1e3 * info.solve_time_s)
        if info.mode != "fast_path":
            qp_drones.append(info.qp_drones)
        max_slack = max(max_slack, info.max_slack_m)
        p_next = p + DT_S * out.command_mps
        min_seg = min(min_seg, min_segment_distance(p, p_next))
        p, done = p_next, j + 1
        if spent > budget_s:
            break
    error = float(np.linalg.norm(p - planner.reference.targets(DT_S * done)[0][0], axis=1).max())
    return {
        "times": times,
        "cpu": cpu,
        "floor": floor,
        "qp_drones": qp_drones,
        "min_seg": min_seg,
        "max_slack": max_slack,
        "steps_run": done,
        "spent": spent,
        "final_error": error,
    }


def bench_case(
    scenario: str,
    n: int,
    mode: str,
    steps: int,
    solver: str = DEFAULT_SOLVER,
    horizon: int = 10,
    budget_s: float = math.inf,
    trace_memory: bool = False,
) -> dict[str, Any]:
    """One (scenario, n, mode): step-time statistics by step kind, peak memory, safety checks."""
    ref, p0 = make_case(scenario, n)
    settings = mode_settings(mode, horizon)
    rss_before = _maxrss_mib()
    planner = MPCPlanner(ref, DT_S, LIMITS, settings, solver=_solver(settings, solver))
    run = _closed_loop(planner, p0, steps, budget_s)
    rss_after = _maxrss_mib()
    times = run["times"]
    qp_ms = times["qp"] + times["fallback"]
    all_ms = qp_ms + times["fast_path"]
    row: dict[str, Any] = {
        "table": "cases",
        "scenario": scenario,
        "n": n,
        "mode": mode,
        "solver": planner.solver_name,
        "horizon": horizon,
        "steps": steps,
        "steps_run": run["steps_run"],
        "qp_steps": len(qp_ms),
        "fast_path_steps": len(times["fast_path"]),
        "fallback_steps": len(times["fallback"]),
        "qp_drones_mean": float(np.mean(run["qp_drones"])) if run["qp_drones"] else 0.0,
        "qp_drones_max": max(run["qp_drones"], default=0),
    }
    row["step_ms_median"], row["step_ms_p90"] = median_p90(all_ms)
    row["step_ms_max"] = max(all_ms, default=float("nan"))
    row["deadline_misses"] = sum(t > 1e3 * DT_S for t in all_ms)  # steps longer than a period
    row["qp_ms_median"], row["qp_ms_p90"] = median_p90(qp_ms)
    row["fast_ms_median"], row["fast_ms_p90"] = median_p90(times["fast_path"])
    cpu = run["cpu"]
    qp_cpu_ms = cpu["qp"] + cpu["fallback"]
    row["cpu_ms_p50"], row["cpu_ms_p99"], row["cpu_ms_max"] = p50_p99_max(qp_cpu_ms + cpu["fast_path"])
    row["qp_cpu_ms_median"], row["qp_cpu_ms_p90"] = median_p90(qp_cpu_ms)
    _, row["qp_cpu_ms_p99"], row["qp_cpu_ms_max"] = p50_p99_max(qp_cpu_ms)
    row["fast_cpu_ms_median"], row["fast_cpu_ms_p90"] = median_p90(cpu["fast_path"])
    floor = solver_floor(*run["floor"])  # wall against wall, the steps that called the solver
    row["solver_steps"], row["solved_ms_median"] = floor.steps, floor.step_ms_median
    row["solver_ms_median"], row["solver_ratio"] = floor.solver_ms_median, floor.ratio
    row["planning_s"] = run["spent"]
    row["rss_peak_mib"], row["rss_delta_mib"] = rss_after, rss_after - rss_before
    row["tracemalloc_peak_mib"] = float("nan")
    if trace_memory:  # a second run: tracing slows allocations, so it is never timed
        tracemalloc.start()
        tracemalloc.reset_peak()
        _closed_loop(
            MPCPlanner(ref, DT_S, LIMITS, settings, solver=_solver(settings, solver)),
            p0,
            run["steps_run"],
            math.inf,
        )
        row["tracemalloc_peak_mib"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    row["min_separation_segments"] = run["min_seg"]
    row["separation_ok"] = bool(run["min_seg"] >= (LIMITS.d_min_m or 0.0) * (1.0 - 1e-9))
    row["max_slack_m"] = run["max_slack"]
    row["final_tracking_error"] = run["final_error"]
    row["blas_threads"] = blas_threads()
    row["note"] = ""
    if run["steps_run"] < steps:
        row["note"] = f"stopped after {run['steps_run']} of {steps} steps (budget {budget_s:g} s)"
    return row


def profile_case(
    scenario: str, n: int, mode: str, steps: int, solver: str = DEFAULT_SOLVER, horizon: int = 10
) -> str:
    """A second run of the case, ``steps`` planner steps under :mod:`cProfile`: its section of the
    ``--profile`` file (:func:`mpcform.bench.profiling.top_functions`)."""
    ref, p0 = make_case(scenario, n)
    settings = mode_settings(mode, horizon)
    planner = MPCPlanner(ref, DT_S, LIMITS, settings, solver=_solver(settings, solver))
    profiler = cProfile.Profile()
    _closed_loop(planner, p0, steps, math.inf, profiler)
    what = f"{scenario} n={n} {mode} ({planner.solver_name})"
    return top_functions(
        profiler, f"bench scale: {what}: {steps} planner steps profiled (a second run, not timed)"
    )


def skipped_row(scenario: str, n: int, mode: str, steps: int, note: str) -> dict[str, Any]:
    """A row for a case that was not run (``note`` says why)."""
    return {
        "table": "cases",
        "scenario": scenario,
        "n": n,
        "mode": mode,
        "steps": steps,
        "steps_run": 0,
        "note": note,
    }


def check_options(
    sizes: Sequence[int],
    scenarios: Sequence[str],
    coupling: str,
    steps: int,
    solver: str,
    horizon: int,
    monolithic_budget_s: float,
) -> list[str]:
    """The modes :func:`run` times; bad sizes, steps or a ``--solver`` a mode ignores fail here."""
    modes = [coupling] + (["monolithic"] if monolithic_budget_s > 0 else [])
    for mode in modes:  # bad input fails here, before any case process starts
        settings = mode_settings(mode, horizon)
        if settings.solves_per_drone and solver != DEFAULT_SOLVER:  # --solver given for a per-drone mode
            raise ValidationError(
                "--solver",
                f"mode {mode!r} solves each drone's QP with DAQP, not "
                f"{solver!r}; time it with --coupling decoupled-sparse",
            )
    smallest = 2 if "crossing" in scenarios else 1
    if steps < 1 or min(sizes, default=smallest) < smallest:
        raise ValidationError(
            "--n/--steps", f"expected n >= {smallest} and steps >= 1, got n = {list(sizes)}, steps = {steps}"
        )
    return modes


def run(
    sizes: Sequence[int] = DEFAULT_N,
    scenarios: Sequence[str] = SCENARIOS,
    coupling: str = "decoupled",
    steps: int = 30,
    solver: str = DEFAULT_SOLVER,
    horizon: int = 10,
    budget_s: float = 60.0,
    monolithic_budget_s: float = 60.0,
    isolate: bool = True,
    trace_memory: bool = False,
    progress: Callable[[str, int, int], None] | None = None,
    profile_path: str | Path | None = None,
) -> list[dict[str, Any]]:
    """Every case, one at a time (never two timed cases at once).

    ``coupling`` is the planner's mode (``decoupled`` or ``joint``, with grouping); each of its
    cases stops after ``budget_s`` of planning time. The monolithic joint QP runs side by side when
    ``monolithic_budget_s > 0``; once one of its cases runs over, its larger sizes are skipped.
    ``isolate`` runs every case in a fresh spawned process (clean peak-memory readings);
    ``progress(label, i, n)`` is called as case ``i`` of ``n`` starts (a skipped one too).
    With ``profile_path``, each case run is run again, as many steps, under :mod:`cProfile` (in a
    fresh process of its own when ``isolate``), and the sections are written there at the end.
    """
    modes = check_options(sizes, scenarios, coupling, steps, solver, horizon, monolithic_budget_s)
    rows: list[dict[str, Any]] = []
    profiles: list[str] = []
    over_budget: dict[tuple[str, str], int] = {}
    total = len(scenarios) * len(sizes) * len(modes)
    with ExitStack() as stack:
        pool = stack.enter_context(process_pool(1, max_tasks_per_child=1)) if isolate else None
        for scenario in scenarios:
            for n in sorted(sizes):
                for mode in modes:
                    budget = monolithic_budget_s if mode == "monolithic" else budget_s
                    skipped = (scenario, mode) in over_budget
                    if progress is not None:
                        what = (
                            "skipped"
                            if skipped
                            else f"{_solver(mode_settings(mode, horizon), solver) or 'DAQP'}"
                        )
                        progress(f"{scenario} n={n} {mode} ({what})", len(rows) + 1, total)
                    if skipped:
                        note = f"skipped: n = {over_budget[scenario, mode]} exceeded the {budget:g} s budget"
                        rows.append(skipped_row(scenario, n, mode, steps, note))
                        continue
                    args = (scenario, n, mode, steps, solver, horizon, budget, trace_memory)
                    row = pool.submit(bench_case, *args).result() if pool is not None else bench_case(*args)
                    rows.append(row)
                    if profile_path is not None:
                        again = (scenario, n, mode, row["steps_run"], solver, horizon)
                        profiles.append(
                            pool.submit(profile_case, *again).result()
                            if pool is not None
                            else profile_case(*again)
                        )
                    if mode == "monolithic" and row["steps_run"] < steps:
                        over_budget[scenario, mode] = n
    if profile_path is not None:
        write_profiles(profile_path, profiles)
    return rows
