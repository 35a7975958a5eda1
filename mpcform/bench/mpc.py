"""``mpcform bench mpc``: per-step cost of the planner against three references to beat.

The references (:mod:`mpcform.bench.mpc_references`): the same QP on a bare persistent solver
object (the framework's overhead), the same MPC written in cvxpy (what a user would write), and
for fast-path steps the eq. 14 rollout over the horizon in plain numpy. QP
steps and fast-path steps are reported apart.

Cases: generated antipodal swaps (planar rings of n drones, spatial spheres) and bundled scenario
files (the swaps by default), each run closed loop on the ideal plant ``p += dt u`` while a
recording backend keeps every QP it sends. Side by side, in the same process:

- **raw**: the step's recorded QPs replayed right after it on a bare persistent solver object
  (``osqp.OSQP`` or ``piqp.SparseSolver``) that, like ours, is set up on a new sparsity pattern
  and updated otherwise: setups count on both sides. The framework overhead ``ours/raw`` is the
  median of the paired per-step ratios (paired, so both see the same load). In decoupled mode
  solved per drone, raw is the time of the step's bare DAQP calls;
- **rollout**: eq. 14 rolled out over the horizon in plain numpy: the yardstick of fast-path steps;
- **cvxpy**: the same QP written in cvxpy with its matrices as constants, built and solved by the
  same solver at every step (a cvxpy user has no fast path; in decoupled mode the same rows as one
  sparse QP with ``--solver``), in every case whose time, extrapolated from its first QPs, fits
  the budget. Rebuilt rather than parametrised: faster here (:func:`mpc_references.cvxpy_replay`).

Every time is given in wall and CPU time (``time.process_time``): medians, 90th percentiles and
ratios. Set ``OPENBLAS_NUM_THREADS=1`` for runs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.bench import mpc_references as refs
from mpcform.bench.problems import DEFAULT_SCENARIOS
from mpcform.bench.stats import median_p90
from mpcform.errors import ValidationError
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings, mode_settings
from mpcform.mpc.strategy import as_sparse
from mpcform.outputs import tables
from mpcform.reference.base import ConstantReference, Reference
from mpcform.scenario.load import load_scenario
from mpcform.solvers.base import QPBackend, QPSolution, SolverOptions
from mpcform.solvers.registry import make_backend
from mpcform.world.bounds import PlanningBounds
from mpcform.world.limits import Limits
from mpcform.world.obstacles import Obstacle

DEFAULT_CVXPY_BUDGET_S = 60.0
"""cvxpy's time budget per case [s] (wall, compilation included)."""


@dataclass
class RecordingBackend(QPBackend):
    """Delegates to ``inner`` and keeps a copy of every problem it is asked to solve.

    Lighter than :class:`mpcform.bench.problems.RecordingBackend` on purpose: it asks the planner for no
    warm start and no context, so the timed steps are the planner's own work."""

    inner: QPBackend
    problems: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.name, self.options = self.inner.name, self.inner.options
        self._current: dict[str, Any] = {}

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        self._current = {"P": P.copy(), "A": A.copy(), "setup": True}
        self._record(q, lo, hi, A.data)
        self.inner.setup(P, q, A, lo, hi)

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        self._current = {**self._current, "setup": False}
        self._record(q, lo, hi, A_data)
        self.inner.update(q, lo, hi, A_data)

    def solve(self, x0: Array | None = None) -> QPSolution:
        return self.inner.solve(x0)

    def _record(self, q: Array, lo: Array, hi: Array, a_data: Array) -> None:
        self.problems.append(
            {**self._current, "q": q.copy(), "l": lo.copy(), "u": hi.copy(), "Ax": a_data.copy()}
        )


@dataclass(frozen=True, eq=False)
class MPCCase:
    """One closed loop: the drones start at ``start_m`` (n, d) and follow ``reference`` for
    ``steps`` steps of ``dt_s`` [s] on the ideal plant, planned with ``settings``."""

    name: str
    reference: Reference
    start_m: Array
    dt_s: float
    steps: int
    limits: Limits | PlanningBounds
    settings: MPCSettings
    obstacles: tuple[Obstacle, ...] = ()

    def planner(self, settings: MPCSettings, solver: str | QPBackend | None) -> MPCPlanner:
        return MPCPlanner(
            self.reference, self.dt_s, self.limits, settings, obstacles=self.obstacles, solver=solver
        )


def swap_case(n: int, dim: int) -> tuple[ConstantReference, Array]:
    """Antipodal swap: drone i starts at -r_i and must reach r_i (ring or Fibonacci sphere)."""
    radius = max(2.0, 0.8 / np.sin(np.pi / n)) if dim == 2 else max(2.0, 0.5 * np.sqrt(n))
    tpl = Template.polygon(n, radius) if dim == 2 else Template.sphere(n, radius)
    return ConstantReference(tpl, FormationState.from_param(np.zeros(dim))), -tpl.offsets.copy()


def generated_case(n: int, dim: int, steps: int, coupling: str) -> MPCCase:
    """The swap of :func:`swap_case` at dt 0.1 s, v_max 1 m/s, d_min 0.5 m, horizon 10."""
    ref, start = swap_case(n, dim)
    name = f"swap {'planar' if dim == 2 else 'spatial'}"
    return MPCCase(
        name, ref, start, 0.1, steps, Limits(v_max_mps=1.0, d_min_m=0.5), mode_settings(coupling, 10)
    )


def scenario_case(path: str | Path, coupling: str) -> MPCCase:
    """A scenario file as it is (its duration, limits and controller settings), planned in the
    mode ``coupling``; it must fly the ideal plant without process noise."""
    sc = load_scenario(path)
    if sc.plant.kind != "ideal" or sc.simulation.noise_std_m > 0:
        raise ValidationError(
            "scenario",
            f"{path}: bench mpc runs scenarios on the ideal plant "
            f"without noise, got plant {sc.plant.kind!r}, noise "
            f"{sc.simulation.noise_std_m:g} m",
        )
    mode = mode_settings(coupling, sc.controller.mpc.horizon)
    solve = sc.controller.mpc.solve if mode.solves_per_drone == sc.controller.mpc.solves_per_drone else None
    settings = replace(
        sc.controller.mpc, coupling=mode.coupling, grouping=mode.grouping, solve=solve or mode.strategy
    )
    limits, obstacles = sc.planned()
    dt = sc.simulation.dt_s
    steps = int(round(sc.simulation.duration_s / dt))
    return MPCCase(sc.name, sc.reference, sc.initial_positions_m, dt, steps, limits, settings, obstacles)


class _Series:
    """Paired wall and CPU times [ms]."""

    def __init__(self) -> None:
        self.wall: list[float] = []
        self.cpu: list[float] = []

    def add(self, t: refs.Times) -> None:
        self.wall.append(t[0])
        self.cpu.append(t[1])

    def stats(self, row: dict[str, Any], key: str) -> None:
        """``key_ms_median``, ``key_ms_p90`` and the same with ``_cpu`` into ``row``."""
        row[f"{key}_ms_median"], row[f"{key}_ms_p90"] = median_p90(self.wall)
        row[f"{key}_cpu_ms_median"], row[f"{key}_cpu_ms_p90"] = median_p90(self.cpu)


def bench_case(
    case: MPCCase, solver: str, cvxpy_solver: str | None, cvxpy_budget_s: float = DEFAULT_CVXPY_BUDGET_S
) -> dict[str, Any]:
    """One case: our step times by mode, the raw-solver, rollout and (optionally) cvxpy references."""
    st = case.settings
    options = as_sparse(st.strategy).options
    rec = RecordingBackend(make_backend(solver, options))
    per_drone = st.solves_per_drone  # then --solver is cvxpy's only
    planner = case.planner(st, None if per_drone else rec)
    p = case.start_m.copy()
    planner.reset(0.0, p)
    ours = {mode: _Series() for mode in ("qp", "fast_path", "fallback")}
    rollout, raw, ratio, whole = _Series(), _Series(), _Series(), (0.0, 0.0)
    replay = refs.RawReplay(solver, options)
    with refs.daqp_meter() if per_drone else nullcontext([0.0, 0.0]) as in_daqp:
        for j in range(case.steps):
            t, recorded, daqp_before = case.dt_s * j, len(rec.problems), tuple(in_daqp)
            clock = refs.Stopwatch()
            out = planner.step(t, p)
            took = clock.ms()
            whole = refs.added(whole, took)
            ours[out.info.mode].add(took)
            if out.info.mode == "fast_path":
                rollout.add(refs.rollout_ms(planner, t, p))
            floor = in_daqp[0] - daqp_before[0], in_daqp[1] - daqp_before[1]
            for pb in rec.problems[recorded:]:  # the step's QPs on the bare solver, right after it
                floor = refs.added(floor, replay.run(pb))
            if out.info.mode == "qp" and floor[0] > 0 and floor[1] > 0:
                raw.add(floor)
                ratio.add((took[0] / floor[0], took[1] / floor[1]))
            p = p + case.dt_s * out.command_mps
    row: dict[str, Any] = {
        "case": case.name,
        "n": case.start_m.shape[0],
        "dim": case.start_m.shape[1],
        "steps": case.steps,
        "solver": planner.solver_name,
        "coupling": st.coupling,
        "qp_steps": len(ours["qp"].wall),
        "fast_path_steps": len(ours["fast_path"].wall),
        "fallback_steps": len(ours["fallback"].wall),
        "setups": sum(1 for pb in rec.problems if pb["setup"]),
        "reused": getattr(rec.inner, "reused", 0),
    }
    ours["qp"].stats(row, "qp")
    raw.stats(row, "raw")
    ours["fast_path"].stats(row, "fast")
    rollout.stats(row, "rollout")
    row["overhead"], row["overhead_cpu"] = median_p90(ratio.wall)[0], median_p90(ratio.cpu)[0]
    row["fast_ratio"] = row["fast_ms_median"] / row["rollout_ms_median"]
    row["fast_ratio_cpu"] = row["fast_cpu_ms_median"] / row["rollout_cpu_ms_median"]
    row["whole_s"], row["whole_cpu_s"] = whole[0] / 1e3, whole[1] / 1e3
    if cvxpy_solver is not None:
        row.update(_cvxpy_row(case, solver, options, cvxpy_solver, cvxpy_budget_s, row))
    return row


def _cvxpy_row(
    case: MPCCase, solver: str, options: SolverOptions, cvxpy: str, budget_s: float, ours: dict[str, Any]
) -> dict[str, Any]:
    """The cvxpy reference: every step's QP recorded without the fast path (per drone: the same
    rows as one sparse QP), solved through cvxpy within ``budget_s``; ratios against ``ours``."""
    full = RecordingBackend(make_backend(solver, options))
    no_fast = case.planner(
        replace(case.settings, fast_path=False, solve=as_sparse(case.settings.strategy)), full
    )
    q = case.start_m.copy()
    no_fast.reset(0.0, q)
    for j in range(case.steps):
        q = q + case.dt_s * no_fast.step(case.dt_s * j, q).command_mps
    res = refs.cvxpy_replay(full.problems, cvxpy, budget_s)
    if res.skipped:
        return {"cvxpy_skipped": res.skipped}
    row: dict[str, Any] = {}
    series = _Series()
    for t in res.times:
        series.add(t)
    series.stats(row, "cvxpy")
    row["cvxpy_speedup_qp"] = row["cvxpy_ms_median"] / ours["qp_ms_median"]
    row["cvxpy_speedup_qp_cpu"] = row["cvxpy_cpu_ms_median"] / ours["qp_cpu_ms_median"]
    row["cvxpy_whole_s"], row["cvxpy_whole_cpu_s"] = res.whole[0] / 1e3, res.whole[1] / 1e3
    row["cvxpy_speedup_whole"] = row["cvxpy_whole_s"] / ours["whole_s"]
    row["cvxpy_speedup_whole_cpu"] = row["cvxpy_whole_cpu_s"] / ours["whole_cpu_s"]
    return row


COLUMNS: list[tuple[str, str, str]] = [
    ("case", "case", "{}"), ("n", "n", "{}"), ("steps", "steps", "{}"), ("qp_steps", "QP", "{}"),
    ("fast_path_steps", "fast", "{}"), ("setups", "setups", "{}"), ("reused", "reused", "{}"),
    ("qp_ms_median", "QP med [ms]", "{:.2f}"), ("qp_ms_p90", "QP p90", "{:.2f}"),
    ("raw_ms_median", "raw med", "{:.2f}"), ("raw_ms_p90", "raw p90", "{:.2f}"),
    ("overhead", "ours/raw", "{:.2f}x"),
    ("fast_ms_median", "fast med [ms]", "{:.3f}"), ("fast_ms_p90", "fast p90", "{:.3f}"),
    ("rollout_ms_median", "numpy rollout", "{:.3f}"), ("fast_ratio", "fast/rollout", "{:.1f}x"),
    ("cvxpy_ms_median", "cvxpy QP med", "{:.1f}"), ("cvxpy_speedup_qp", "vs cvxpy (QP)", "{:.1f}x"),
    ("whole_s", "whole [s]", "{:.2f}"), ("cvxpy_whole_s", "cvxpy whole", "{:.2f}"),
    ("cvxpy_speedup_whole", "vs cvxpy (whole)", "{:.1f}x"),
]  # fmt: skip # the columns read best as a table: key, header, format
"""Columns; a time or ratio column shows ``wall / CPU`` (its key and the key with ``_cpu``)."""


def cpu_key(key: str) -> str:
    """The record key of the CPU-time twin of ``key`` (``qp_ms_median`` -> ``qp_cpu_ms_median``,
    ``whole_s`` -> ``whole_cpu_s``, ``overhead`` -> ``overhead_cpu``)."""
    if "_ms_" in key:
        return key.replace("_ms_", "_cpu_ms_", 1)
    return f"{key[:-2]}_cpu_s" if key.endswith("_s") else f"{key}_cpu"


def _paired(fmt: str) -> Callable[[Any], str]:
    """Formatter of a ``(wall, CPU)`` cell."""

    def one(value: Any) -> str:
        return "-" if value is None or not np.isfinite(value) else fmt.format(value)

    return lambda pair: "-" if pair == (None, None) else f"{one(pair[0])} / {one(pair[1])}"


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a markdown table, times and ratios as ``wall / CPU`` (missing or NaN: ``-``),
    a line saying so, then one line per case whose cvxpy run was skipped, with the reason."""
    pairs = {key: _paired(fmt) for key, _, fmt in COLUMNS if fmt != "{}"}
    shown = [{**r, **{key: (r.get(key), r.get(cpu_key(key))) for key in pairs}} for r in rows]
    notes = [
        f"cvxpy skipped for {r['case']} (n = {r['n']}): {r['cvxpy_skipped']}"
        for r in rows
        if r.get("cvxpy_skipped")
    ]
    table = tables.markdown_table(shown, COLUMNS, pairs)
    return "\n".join([table, "", "Times and ratios: wall / CPU (process time).", *notes])


def check_cases(
    planar_n: Sequence[int],
    spatial_n: Sequence[int],
    steps: int,
    scenarios: Sequence[str | Path],
    coupling: str,
) -> list[MPCCase]:
    """Swaps of >= 2 drones, >= 1 step and at least one case, else a :class:`ValidationError`;
    the scenario files' cases (a file that is no case fails here)."""
    if steps < 1 or any(n < 2 for n in (*planar_n, *spatial_n)):
        got = f"--n {list(planar_n)}, --spatial-n {list(spatial_n)}, --steps {steps}"
        raise ValidationError(
            "--n/--spatial-n/--steps", f"expected swaps of >= 2 drones and >= 1 step, got {got}"
        )
    if not (planar_n or spatial_n or scenarios):
        raise ValidationError("--n", "no case to run: give --n, --spatial-n or --scenarios")
    return [scenario_case(path, coupling) for path in scenarios]


def run(
    planar_n: Sequence[int],
    spatial_n: Sequence[int],
    steps: int,
    solver: str,
    coupling: str,
    cvxpy_budget_s: float = DEFAULT_CVXPY_BUDGET_S,
    scenarios: Sequence[str | Path] = DEFAULT_SCENARIOS,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """The generated swaps, then the scenario files; cvxpy in every case that fits
    ``cvxpy_budget_s`` (0: none). Bad sizes, steps or no case at all fail before any case runs.
    ``progress(label, i, n)`` is called as case ``i`` of ``n`` starts."""
    from_files = check_cases(planar_n, spatial_n, steps, scenarios, coupling)
    cases = [
        generated_case(n, dim, steps, coupling)
        for dim, sizes in ((2, planar_n), (3, spatial_n))
        for n in sizes
    ]
    cases += from_files
    cvxpy_solver = solver if cvxpy_budget_s > 0 and _have_cvxpy() else None
    rows = []
    for i, case in enumerate(cases, 1):
        if progress is not None:
            cvxpy = f", cvxpy within {cvxpy_budget_s:g} s" if cvxpy_solver else ""
            label = f"{case.name} n={case.start_m.shape[0]} ({solver}, {coupling}{cvxpy})"
            progress(label, i, len(cases))
        rows.append(bench_case(case, solver, cvxpy_solver, cvxpy_budget_s))
    return rows


def _have_cvxpy() -> bool:
    try:
        import cvxpy  # noqa: F401
    except ImportError:
        return False
    return True
