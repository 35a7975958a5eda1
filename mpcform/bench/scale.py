"""``mpcform bench scale``: planner step time and peak memory from tens to a thousand drones.

Two spatial scenarios at constant density (lattice spacing ``SPACING_M``, so the occupied volume
grows with n), horizon 10, ``dt = 0.1 s``, ``v_max = 1 m/s``, ``d_min = 0.5 m``:

- **formation**: a cubic grid formation translating and turning about z
  (:class:`~mpcform.reference.base.ExponentialReference`, rate 0.1/s; at the start the centroid moves
  at 0.3 m/s and the outermost drone turns at 0.2 m/s, so reference speeds stay well inside the
  velocity polytope and the fast path normally applies), drones starting on the reference with
  a seeded 5 cm perturbation;
- **crossing**: two slab-shaped grid formations (two layers deep along x) flying head-on
  through each other at 0.5 m/s each, laterally offset by less than ``d_min`` so that every
  drone of a column meets the drones of the opposite column (:class:`CrossingReference`). The
  run starts with the fronts one spacing apart, so the measured steps are inside the crossing.

Each case runs a fixed number of closed-loop steps with exact execution; only
:meth:`MPCPlanner.step` is timed. Modes: ``decoupled`` (``coupling="decoupled"``, grouping,
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

import math
import resource
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.geometry import min_segment_distance
from mpcform.formation.kinematics import velocity_size
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.limits import Limits
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.outputs import tables
from mpcform.reference.base import ExponentialReference, Profile, Reference
from mpcform.run.parallel import blas_threads, process_pool
from mpcform.solvers.registry import DEFAULT_SOLVER

SCENARIOS = ("formation", "crossing")
MODES = ("decoupled", "decoupled-sparse", "joint", "monolithic")
PLANNER_MODES = MODES[:-1]  # the grouped modes (--coupling)
DEFAULT_N = (10, 30, 100, 300, 1000)
SPACING_M = 1.5  # lattice spacing of every formation [m] (constant density)
LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5)
DT_S = 0.1
FORMATION_RATE_PER_S = 0.1  # ExponentialReference rate
FORMATION_TRANSLATION_MPS = 0.3  # centroid speed at t = 0
FORMATION_RIM_MPS = 0.2  # speed of the outermost drone due to the turn, at t = 0
FORMATION_PERTURBATION_M = 0.05
CROSSING_SPEED_MPS = 0.5  # each slab's speed; they close at twice this
CROSSING_LATERAL_M = (0.15, 0.1)  # y, z offset of the second slab's columns (< d_min)
GROWTH_MIN_N = 100  # exponents are fitted over n >= this


class CrossingReference(Reference):
    """Drone ``i``'s target moves from ``start_m[i]`` at constant ``velocity_mps[i]``.

    Two groups flying through each other are not a rigid formation motion, so :meth:`targets`
    is given directly; :meth:`profile` describes the (centred) template at rest.
    """

    def __init__(self, start_m: Array, velocity_mps: Array) -> None:
        self.template, shift = Template.centred(start_m, name="crossing")
        self.start_m = np.asarray(start_m, dtype=float) - shift
        self.velocity_mps = np.asarray(velocity_mps, dtype=float)

    def profile(self, times_s: Array) -> Profile:
        t, d = times_s.shape[0], self.template.dim
        zeros = np.zeros((t, d))
        return Profile(zeros, np.broadcast_to(np.eye(d), (t, d, d)), np.ones(t), zeros,
                       np.zeros((t, velocity_size(d) - d - 1)), np.zeros(t))  # fmt: skip

    def targets(self, times_s: object) -> tuple[Array, Array]:
        t = np.atleast_1d(np.asarray(times_s, dtype=float))
        pos = self.start_m + t[:, None, None] * self.velocity_mps
        return pos, np.broadcast_to(self.velocity_mps, pos.shape).copy()


def lattice(n: int, shape: Sequence[int], spacing_m: float = SPACING_M) -> Array:
    """The first ``n`` points (n, len(shape)) of a ``shape`` lattice (row-major order), centred along
    every axis but the first."""
    axes = [spacing_m * np.arange(k) for k in shape]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(shape))[:n]
    pts[:, 1:] -= 0.5 * spacing_m * (np.asarray(shape[1:]) - 1)
    return pts


def formation_case(n: int, seed: int = 0) -> tuple[Reference, Array]:
    """Grid formation translating and turning about z; start positions (n, 3) near its start."""
    side = max(1, math.ceil(round(n ** (1.0 / 3.0), 9)))
    tpl, _ = Template.centred(lattice(n, (side, side, side)), name="grid")
    rim = max(float(np.linalg.norm(tpl.offsets, axis=1).max()), SPACING_M)
    lam = FORMATION_RATE_PER_S
    move = FORMATION_TRANSLATION_MPS / lam * np.array([2.0, 1.0, 0.5]) / np.sqrt(5.25)
    start = FormationState.from_param(np.array([0.0, 0.0, 20.0]))
    turn = np.array([0.0, 0.0, FORMATION_RIM_MPS / (lam * rim)])  # rotation vector [rad]
    goal = FormationState.from_param(start.centroid_m + move, turn)
    ref = ExponentialReference(tpl, start, goal, lam)
    rng = np.random.default_rng([seed, n])
    p0 = ref.targets(0.0)[0][0] + rng.normal(0.0, FORMATION_PERTURBATION_M, (n, 3))
    return ref, p0


def crossing_case(n: int, gap_m: float = SPACING_M) -> tuple[Reference, Array]:
    """Two slabs (2 layers deep along x), fronts ``gap_m`` apart, flying head-on through each other."""
    if n < 2:
        raise ValidationError("n", f"a crossing needs at least 2 drones, got {n}")
    m_a, m_b = n // 2, n - n // 2
    face = math.ceil(m_b / 2)
    width = math.ceil(math.sqrt(face))
    shape = (2, width, math.ceil(face / width))
    a = lattice(m_a, shape)
    b = lattice(m_b, shape) * np.array([-1.0, 1.0, 1.0])  # layers mirrored: the fronts face each other
    a[:, 0] -= 0.5 * gap_m + SPACING_M  # front layer at x = -gap/2
    b[:, 0] += 0.5 * gap_m + SPACING_M
    b[:, 1:] += CROSSING_LATERAL_M
    velocity = np.zeros((n, 3))
    velocity[:m_a, 0], velocity[m_a:, 0] = CROSSING_SPEED_MPS, -CROSSING_SPEED_MPS
    ref = CrossingReference(np.vstack([a, b]), velocity)
    return ref, ref.targets(0.0)[0][0].copy()


def make_case(scenario: str, n: int) -> tuple[Reference, Array]:
    """Reference and start positions of a scenario of ``SCENARIOS``."""
    if scenario == "formation":
        return formation_case(n)
    if scenario == "crossing":
        return crossing_case(n)
    raise ValueError(f"unknown scenario {scenario!r}, expected one of {SCENARIOS}")


def mode_settings(mode: str, horizon: int) -> MPCSettings:
    """Planner settings of a mode of ``MODES``."""
    if mode == "monolithic":
        return MPCSettings(horizon=horizon, coupling="joint", grouping=False)
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}, expected one of {MODES}")
    coupling, _, solve = mode.partition("-")
    return MPCSettings(horizon=horizon, coupling=coupling, grouping=True, per_drone=solve != "sparse")


def _solver(settings: MPCSettings, solver: str) -> str:
    """The backend for a mode: the per-drone decoupled mode takes no sparse solver."""
    return DEFAULT_SOLVER if settings.solves_per_drone else solver


def _maxrss_mib() -> float:
    """Peak resident set size of this process [MiB] (ru_maxrss is KiB on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


def _stats(ms: list[float]) -> tuple[float, float]:
    if not ms:
        return float("nan"), float("nan")
    return float(np.median(ms)), float(np.percentile(ms, 90))


def _closed_loop(planner: MPCPlanner, p: Array, steps: int, budget_s: float) -> dict[str, Any]:
    """Run ``steps`` steps (or until ``budget_s`` of planning time); time every planner call."""
    planner.reset(0.0, p)
    times: dict[str, list[float]] = {"qp": [], "fast_path": [], "fallback": []}
    qp_drones: list[int] = []
    min_seg, max_slack, spent = float("inf"), 0.0, 0.0
    done = 0
    for j in range(steps):
        start = time.perf_counter()
        out = planner.step(DT_S * j, p)
        elapsed = time.perf_counter() - start
        spent += elapsed
        times[out.info.mode].append(1e3 * elapsed)
        if out.info.mode != "fast_path":
            qp_drones.append(out.info.qp_drones)
        max_slack = max(max_slack, out.info.max_slack_m)
        p_next = p + DT_S * out.command_mps
        min_seg = min(min_seg, min_segment_distance(p, p_next))
        p, done = p_next, j + 1
        if spent > budget_s:
            break
    error = float(np.linalg.norm(p - planner.reference.targets(DT_S * done)[0][0], axis=1).max())
    return {"times": times, "qp_drones": qp_drones, "min_seg": min_seg, "max_slack": max_slack,
            "steps_run": done, "spent": spent, "final_error": error}  # fmt: skip


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
        "table": "cases", "scenario": scenario, "n": n, "mode": mode, "solver": planner.solver_name,
        "horizon": horizon,
        "steps": steps,
        "steps_run": run["steps_run"], "qp_steps": len(qp_ms), "fast_path_steps": len(times["fast_path"]),
        "fallback_steps": len(times["fallback"]),
        "qp_drones_mean": float(np.mean(run["qp_drones"])) if run["qp_drones"] else 0.0,
        "qp_drones_max": max(run["qp_drones"], default=0),
    }  # fmt: skip
    row["step_ms_median"], row["step_ms_p90"] = _stats(all_ms)
    row["step_ms_max"] = max(all_ms, default=float("nan"))
    row["qp_ms_median"], row["qp_ms_p90"] = _stats(qp_ms)
    row["fast_ms_median"], row["fast_ms_p90"] = _stats(times["fast_path"])
    row["planning_s"] = run["spent"]
    row["rss_peak_mib"], row["rss_delta_mib"] = rss_after, rss_after - rss_before
    row["tracemalloc_peak_mib"] = float("nan")
    if trace_memory:  # a second run: tracing slows allocations, so it is never timed
        tracemalloc.start()
        tracemalloc.reset_peak()
        _closed_loop(MPCPlanner(ref, DT_S, LIMITS, settings, solver=_solver(settings, solver)), p0,
                     run["steps_run"], math.inf)  # fmt: skip
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


def growth_exponent(n: Sequence[float], t: Sequence[float], n_min: float = GROWTH_MIN_N) -> float:
    """Least-squares slope of ``log t`` against ``log n`` over the points with ``n >= n_min`` and a
    finite positive time (NaN with fewer than two such points at distinct n)."""
    x, y = np.asarray(n, dtype=float), np.asarray(t, dtype=float)
    ok = (x >= n_min) & np.isfinite(y) & (y > 0)
    if np.unique(x[ok]).shape[0] < 2:
        return float("nan")
    slope, _ = np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)
    return float(slope)


def two_point_exponent(n: Sequence[float], t: Sequence[float], a: float = 100, b: float = 1000) -> float:
    """``log(t(b) / t(a)) / log(b / a)`` (NaN unless both sizes have a finite positive time)."""
    at = {float(k): float(v) for k, v in zip(n, t, strict=True) if np.isfinite(v) and v > 0}
    if float(a) not in at or float(b) not in at:
        return float("nan")
    return math.log(at[float(b)] / at[float(a)]) / math.log(b / a)


def growth_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Growth exponents per (scenario, mode) of the median step time and the median QP-step time.

    Cases stopped by their budget count with the steps they ran (listed under ``partial``)."""
    out = []
    for scenario, mode in dict.fromkeys((r["scenario"], r["mode"]) for r in rows):
        case = [r for r in rows if (r["scenario"], r["mode"]) == (scenario, mode) and r.get("steps_run")]
        ns = [r["n"] for r in case]
        rec: dict[str, Any] = {"table": "growth", "scenario": scenario, "mode": mode, "sizes": ns,
                               "partial": [r["n"] for r in case if r["steps_run"] < r["steps"]]}  # fmt: skip
        for key, name in (("step_ms_median", "step"), ("qp_ms_median", "qp")):
            t = [r.get(key, float("nan")) for r in case]
            rec[f"{name}_exponent_fit"] = growth_exponent(ns, t)
            rec[f"{name}_exponent_100_1000"] = two_point_exponent(ns, t)
        out.append(rec)
    return out


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
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Every case, one at a time (never two timed cases at once).

    ``coupling`` is the planner's mode (``decoupled`` or ``joint``, with grouping); each of its
    cases stops after ``budget_s`` of planning time. The monolithic joint QP runs side by side when
    ``monolithic_budget_s > 0``; once one of its cases runs over, its larger sizes are skipped.
    ``isolate`` runs every case in a fresh spawned process (clean peak-memory readings);
    ``progress`` is called with a line per finished case.
    """
    modes = [coupling] + (["monolithic"] if monolithic_budget_s > 0 else [])
    for mode in modes:  # bad input fails here, before any case process starts
        settings = mode_settings(mode, horizon)
        if solver != _solver(settings, solver):
            raise ValidationError("--solver", f"mode {mode!r} solves each drone's QP with DAQP, not "
                                  f"{solver!r}; time it with --coupling decoupled-sparse")  # fmt: skip
    smallest = 2 if "crossing" in scenarios else 1
    if steps < 1 or min(sizes, default=smallest) < smallest:
        raise ValidationError("--n/--steps", f"expected n >= {smallest} and steps >= 1, got n = "
                              f"{list(sizes)}, steps = {steps}")  # fmt: skip
    rows: list[dict[str, Any]] = []
    over_budget: dict[tuple[str, str], int] = {}
    with ExitStack() as stack:
        pool = stack.enter_context(process_pool(1, max_tasks_per_child=1)) if isolate else None
        for scenario in scenarios:
            for n in sorted(sizes):
                for mode in modes:
                    budget = monolithic_budget_s if mode == "monolithic" else budget_s
                    if (scenario, mode) in over_budget:
                        note = f"skipped: n = {over_budget[scenario, mode]} exceeded the {budget:g} s budget"
                        rows.append(skipped_row(scenario, n, mode, steps, note))
                        continue
                    args = (scenario, n, mode, steps, solver, horizon, budget, trace_memory)
                    row = pool.submit(bench_case, *args).result() if pool is not None else bench_case(*args)
                    rows.append(row)
                    if progress is not None:
                        progress(f"bench scale: {scenario} n={n} {mode}: median step "
                                 f"{row['step_ms_median']:.1f} ms over {row['steps_run']} steps")  # fmt: skip
                    if mode == "monolithic" and row["steps_run"] < steps:
                        over_budget[scenario, mode] = n
    return rows


COLUMNS = [
    ("scenario", "scenario", "{}"), ("n", "n", "{}"), ("mode", "mode", "{}"), ("steps_run", "steps", "{}"),
    ("qp_steps", "QP", "{}"), ("fast_path_steps", "fast", "{}"), ("fallback_steps", "fallback", "{}"),
    ("qp_drones_mean", "QP drones", "{:.0f}"), ("step_ms_median", "step med [ms]", "{:.2f}"),
    ("step_ms_p90", "step p90", "{:.2f}"), ("qp_ms_median", "QP med [ms]", "{:.2f}"),
    ("qp_ms_p90", "QP p90", "{:.2f}"), ("fast_ms_median", "fast med [ms]", "{:.2f}"),
    ("fast_ms_p90", "fast p90", "{:.2f}"), ("rss_peak_mib", "peak RSS [MiB]", "{:.0f}"),
    ("rss_delta_mib", "RSS growth", "{:.0f}"), ("tracemalloc_peak_mib", "traced peak", "{:.0f}"),
    ("min_separation_segments", "min sep [m]", "{:.3f}"), ("note", "note", "{}"),
]  # fmt: skip

GROWTH_COLUMNS = [
    ("scenario", "scenario", "{}"), ("mode", "mode", "{}"),
    ("step_exponent_fit", "step: fit n>=100", "{:.2f}"),
    ("step_exponent_100_1000", "step: 100->1000", "{:.2f}"),
    ("qp_exponent_fit", "QP step: fit n>=100", "{:.2f}"),
    ("qp_exponent_100_1000", "QP step: 100->1000", "{:.2f}"),
    ("partial", "stopped early (n)", "{}"),
]  # fmt: skip


def markdown_table(rows: list[dict[str, Any]], columns: list[tuple[str, str, str]] | None = None) -> str:
    """The rows as a markdown table (missing or NaN entries shown as ``-``)."""
    return tables.markdown_table(rows, COLUMNS if columns is None else columns)

def target_lines(rows: list[dict[str, Any]], growth: list[dict[str, Any]], coupling: str) -> list[str]:
    """The acceptance targets of the scaling issue for the planner mode ``coupling``, each with what
    was measured (``-`` where not measured; cases stopped by their budget say so)."""

    def case(scenario: str, n: int) -> dict[str, Any]:
        match = [r for r in rows if (r["scenario"], r["n"], r["mode"]) == (scenario, n, coupling)]
        return match[0] if match and match[0].get("steps_run") else {}

    def num(value: float, fmt: str) -> str:
        return fmt.format(value) if np.isfinite(value) else "-"

    def verdict(value: float, limit: float, row: dict[str, Any] | None = None) -> str:
        if not np.isfinite(value):
            return "not measured"
        partial = row is not None and row["steps_run"] < row["steps"]
        return ("met" if value <= limit else "MISSED") + (f" ({row['note']})" if partial and row else "")

    form = case("formation", 1000)
    med, p90 = form.get("step_ms_median", math.nan), form.get("step_ms_p90", math.nan)
    lines = [f"formation n=1000 median step {num(med, '{:.1f}')} ms (p90 {num(p90, '{:.1f}')}) <= 100 ms: "
             f"{verdict(med, 100.0, form)}"]  # fmt: skip
    cross = case("crossing", 100)
    qp = cross.get("qp_ms_median", math.nan)
    lines.append(f"crossing n=100 median QP step {num(qp, '{:.1f}')} ms <= 50 ms: {verdict(qp, 50.0, cross)}")
    for g in growth:
        if g["mode"] == coupling:
            e = g["step_exponent_100_1000"]
            partial = f" (from cases stopped early: n = {g['partial']})" if g["partial"] else ""
            text = f"{g['scenario']} growth exponent 100->1000 (median step) {num(e, '{:.2f}')} <= 1.2"
            lines.append(f"{text}: {verdict(e, 1.2)}{partial}")
    peaks = [case(s, 1000).get("rss_peak_mib", math.nan) for s in SCENARIOS]
    peak = max((x for x in peaks if np.isfinite(x)), default=math.nan)
    lines.append(f"peak RSS of the n=1000 runs {num(peak, '{:.0f}')} MiB <= 1 GiB: {verdict(peak, 1024.0)}")
    return lines


def report(rows: list[dict[str, Any]], coupling: str) -> tuple[str, list[dict[str, Any]]]:
    """Markdown (cases, growth exponents, targets) and the growth records."""
    growth = growth_rows([r for r in rows if r.get("steps_run")])
    text = "\n\n".join([
        markdown_table(rows),
        markdown_table(growth, GROWTH_COLUMNS),
        "\n".join(f"- {line}" for line in target_lines(rows, growth, coupling)),
    ])  # fmt: skip
    return text, growth
