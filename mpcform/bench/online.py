"""The online loop's deadline (``mpcform bench online``): step times and deadline fallbacks.

Each case is a crossing of ``mpcform bench scale`` (two slabs flying head-on through each other;
:mod:`mpcform.bench.scale_cases`) of n drones, planned online (:class:`~mpcform.online.loop.
OnlineLoop`) with a deadline of ``budget_s`` (default one period, dt = 0.1 s) and the ideal plant
as the measurement. Reported per n: wall and CPU p50 / p99 / max of the steps, the share that
missed the deadline (and so sent the braking fallback), how far the latest step ran past the
budget, the bare solver floor (the median wall time inside the solver calls of the steps that
called the solver, each step's ``solve_time_s``) and the ratio of those steps' median wall time to
it, the closest pair along the straight segments, the largest final tracking error and the share
of drones within 0.1 m of their targets at the end (completion). Over the sizes: the growth
exponent of the CPU p50 (:func:`mpcform.bench.growth.growth_exponent`). With ``profile_path``
each case is flown again under :mod:`cProfile` (:mod:`mpcform.bench.profiling`).
"""

from __future__ import annotations

import cProfile
import math
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.bench.growth import GROWTH_MIN_N, growth_exponent
from mpcform.bench.profiling import top_functions, write_profiles
from mpcform.bench.scale_cases import DT_S, LIMITS, crossing_case
from mpcform.bench.stats import solver_floor
from mpcform.formation.geometry import min_segment_distance
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.online.loop import IdealPlanWarning, OnlineLoop, OnlineStep, step_time_stats
from mpcform.outputs import tables

DEFAULT_N = (20, 100, 1000)
DEFAULT_STEPS = 60  # 6 s: the slabs meet, cross and part
COMPLETION_M = 0.1  # a drone this close to its target at the end has completed (as run's metric)

COLUMNS = (
    ("n", "drones", "{:.0f}"),
    ("coupling", "coupling", "{}"),
    ("wall_p50_ms", "wall p50 [ms]", "{:.2f}"),
    ("wall_p99_ms", "wall p99 [ms]", "{:.1f}"),
    ("wall_max_ms", "wall max [ms]", "{:.1f}"),
    ("cpu_p50_ms", "CPU p50 [ms]", "{:.2f}"),
    ("cpu_p99_ms", "CPU p99 [ms]", "{:.1f}"),
    ("cpu_max_ms", "CPU max [ms]", "{:.1f}"),
    ("deadline_miss_share", "deadline misses", "{:.1%}"),
    ("overrun_max_ms", "max past budget [ms]", "{:.1f}"),
    ("solver_steps", "solver steps", "{}"),
    ("solver_ms_median", "solver med [ms]", "{:.2f}"),
    ("solver_ratio", "step / solver", "{:.2f}"),
    ("min_distance_m", "min distance [m]", "{:.3f}"),
    ("final_error_m", "final error [m]", "{:.3f}"),
    ("completion", "completion", "{:.0%}"),
)


def _fly(
    n: int, steps: int, budget_s: float, coupling: str, profiler: cProfile.Profile | None = None
) -> tuple[list[OnlineStep], Array, float, Array]:
    """The crossing of ``n`` drones flown online for ``steps`` periods (``profiler`` enabled around
    each online step): the steps, the final positions, the closest pair along the straight
    segments and the final targets."""
    reference, p = crossing_case(n)
    settings = MPCSettings(coupling=coupling, step_budget_s=budget_s)
    with warnings.catch_warnings():  # flown on the ideal plant: planned for it on purpose
        warnings.simplefilter("ignore", IdealPlanWarning)
        loop = OnlineLoop(MPCPlanner(reference, DT_S, LIMITS, settings))
    done, closest = [], np.inf
    for k in range(steps):
        if profiler is not None:
            profiler.enable()
        step = loop.step(k * DT_S, p)
        if profiler is not None:
            profiler.disable()
        p_next = p + DT_S * step.command_mps
        closest = min(closest, min_segment_distance(p, p_next))
        p = p_next
        done.append(step)
    return done, p, float(closest), reference.targets(steps * DT_S)[0][0]


def bench_online(n: int, steps: int, budget_s: float, coupling: str = "decoupled") -> dict[str, Any]:
    """One crossing of ``n`` drones planned online for ``steps`` periods (module docstring)."""
    done, p, closest, targets = _fly(n, steps, budget_s, coupling)
    stats = step_time_stats(done)
    error = np.linalg.norm(p - targets, axis=1)
    row: dict[str, Any] = {
        "table": "cases",
        "n": n,
        "coupling": coupling,
        "steps": steps,
        "budget_s": budget_s,
    }
    row |= {k.replace("_s", "_ms"): 1e3 * v for k, v in stats.items() if k.endswith("_s")}
    row["deadline_miss_share"] = stats["deadline_miss_share"]
    row["overrun_max_ms"] = 1e3 * max(0.0, max(s.wall_s for s in done) - budget_s)
    solver_ms = [1e3 * getattr(s.info, "solve_time_s", 0.0) for s in done]
    floor = solver_floor([1e3 * s.wall_s for s in done], solver_ms)  # the steps that called the solver
    row["solver_steps"], row["solved_wall_p50_ms"] = floor.steps, floor.step_ms_median
    row["solver_ms_median"], row["solver_ratio"] = floor.solver_ms_median, floor.ratio
    row |= {"min_distance_m": closest, "final_error_m": float(error.max())}
    return row | {"completion": float(np.mean(error <= COMPLETION_M))}


def profile_online(n: int, steps: int, budget_s: float, coupling: str = "decoupled") -> str:
    """The crossing flown again with its online steps under :mod:`cProfile`: its section of the
    ``--profile`` file (:func:`mpcform.bench.profiling.top_functions`)."""
    profiler = cProfile.Profile()
    _fly(n, steps, budget_s, coupling, profiler)
    what = f"crossing n={n} ({coupling}, deadline {budget_s:g} s)"
    return top_functions(
        profiler, f"bench online: {what}: {steps} online steps profiled (a second run, not timed)"
    )


def run(
    ns: tuple[int, ...],
    steps: int,
    budget_s: float,
    coupling: str = "decoupled",
    progress: Callable[[str, int, int], None] | None = None,
    profile_path: str | Path | None = None,
) -> list[dict[str, Any]]:
    """:func:`bench_online` for every n of ``ns``; ``progress(label, i, n)`` as case ``i`` starts.
    With ``profile_path``, each case is flown again under :mod:`cProfile` right after it, and the
    sections are written there at the end."""
    rows, profiles = [], []
    for i, n in enumerate(ns, 1):
        if progress is not None:
            solver = "DAQP per drone" if coupling == "decoupled" else "piqp"
            progress(f"crossing n={n} ({coupling}, {solver}, {steps} steps)", i, len(ns))
        rows.append(bench_online(n, steps, budget_s, coupling))
        if profile_path is not None:
            profiles.append(profile_online(n, steps, budget_s, coupling))
    if profile_path is not None:
        write_profiles(profile_path, profiles)
    return rows


def growth(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The growth record: the exponent of the CPU p50 over n, fitted over n >= 100
    (:func:`mpcform.bench.growth.growth_exponent`; NaN with fewer than two such sizes)."""
    ns = [r["n"] for r in rows]
    e = growth_exponent(ns, [r["cpu_p50_ms"] for r in rows])
    return {
        "table": "growth",
        "coupling": rows[0]["coupling"] if rows else "",
        "sizes": ns,
        "cpu_p50_exponent_fit": e,
    }


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a markdown table, then the largest n whose p99 met the budget with no miss and
    the growth exponent of the CPU p50."""
    met = [r["n"] for r in rows if r["wall_p99_ms"] < 1e3 * r["budget_s"] and r["deadline_miss_share"] == 0]
    line = f"largest n with wall p99 < budget and no deadline miss: {max(met) if met else 'none'}"
    e = growth(rows)["cpu_p50_exponent_fit"]
    shown = f"{e:.2f}" if math.isfinite(e) else f"- (needs two sizes >= {GROWTH_MIN_N})"
    fit = f"growth exponent of the CPU p50 over n (fit n>={GROWTH_MIN_N}): {shown}"
    return tables.markdown_table(rows, COLUMNS) + "\n\n" + line + "\n" + fit
