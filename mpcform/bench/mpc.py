"""``mpcform bench mpc``: per-step cost of the planner against three references to beat.

The references: the same QP on a bare persistent solver object (the framework's overhead), the
same MPC written in cvxpy with parameters (what a user would write), and for fast-path steps the
eq. 14 rollout over the horizon in plain numpy. QP steps and fast-path steps are reported apart.

For each antipodal swap (planar rings of n drones, and spatial spheres) the planner runs closed
loop while a recording backend keeps every QP it sends. Side by side, in the same process:

- **raw**: each recorded QP replayed, right after our step, on a bare persistent solver object
  (``osqp.OSQP`` or ``piqp.SparseSolver``), update + solve only: the framework overhead is the
  median of the paired ratios of our QP-step time over this (paired, so both see the same load).
  In decoupled mode solved per drone, raw is the time of the step's bare DAQP calls;
- **rollout**: eq. 14 rolled out over the horizon in plain numpy (reference targets included):
  the yardstick of fast-path steps;
- **cvxpy**: the same QP written in cvxpy with parameters (cost vector, bounds, and the values
  of A, ``A(v) z = R (v * (C z))`` with constant selections R and C), solved by the same
  solver through cvxpy for every step of the scenario (a cvxpy user has no fast path); in
  decoupled mode (solved per drone) the same rows as one sparse QP with ``--solver``.

Times are wall-clock medians and 90th percentiles; set ``OPENBLAS_NUM_THREADS=1`` for runs.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.bench.stats import median_p90
from mpcform.control.base import feedforward_targets
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.limits import Limits
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import mode_settings
from mpcform.outputs import tables
from mpcform.reference.base import ConstantReference
from mpcform.solvers.base import QPBackend, QPSolution, SolverOptions
from mpcform.solvers.registry import DEFAULT_SOLVER, make_backend


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


def swap_case(n: int, dim: int) -> tuple[ConstantReference, Array]:
    """Antipodal swap: drone i starts at -r_i and must reach r_i (ring or Fibonacci sphere)."""
    radius = max(2.0, 0.8 / np.sin(np.pi / n)) if dim == 2 else max(2.0, 0.5 * np.sqrt(n))
    tpl = Template.polygon(n, radius) if dim == 2 else Template.sphere(n, radius)
    return ConstantReference(tpl, FormationState.from_param(np.zeros(dim))), -tpl.offsets.copy()


class _RawSolver:
    """A bare persistent solver object fed the recorded QPs one by one (same settings as ours)."""

    def __init__(self, solver: str, options: SolverOptions) -> None:
        self.solver, self.options = solver, options
        self._raw: Any = None

    def run(self, pb: dict[str, Any]) -> float | None:
        """Set up (new pattern: returns None) or update + solve, returning the time [ms]."""
        o = self.options
        if self.solver == "osqp":
            import osqp

            if pb["setup"]:
                self._raw = osqp.OSQP()
                self._raw.setup(pb["P"], pb["q"], pb["A"], pb["l"], pb["u"], verbose=False, eps_abs=o.eps_abs,
                                eps_rel=o.eps_rel, max_iter=o.max_iter, polishing=True)  # fmt: skip
                self._raw.solve(raise_error=False)
                return None
            start = time.perf_counter()
            self._raw.update(q=pb["q"], l=pb["l"], u=pb["u"], Ax=pb["Ax"])
            self._raw.solve(raise_error=False)
            return 1e3 * (time.perf_counter() - start)
        import piqp

        eq = pb["l"] == pb["u"]
        if pb["setup"]:
            ids = pb["A"].copy()
            ids.data = np.arange(ids.nnz, dtype=float)
            self._a_eq, self._g = ids[eq].tocsc(), ids[~eq].tocsc()
            self._eq_ids, self._g_ids = self._a_eq.data.astype(np.intp), self._g.data.astype(np.intp)
            self._a_eq.data, self._g.data = pb["Ax"][self._eq_ids], pb["Ax"][self._g_ids]
            self._raw = piqp.SparseSolver()
            self._raw.settings.verbose = False
            self._raw.settings.eps_abs, self._raw.settings.eps_rel = o.eps_abs, o.eps_rel
            self._raw.setup(pb["P"], pb["q"], self._a_eq, pb["l"][eq], self._g, pb["l"][~eq], pb["u"][~eq])
            self._raw.solve()
            return None
        start = time.perf_counter()
        self._a_eq.data, self._g.data = pb["Ax"][self._eq_ids], pb["Ax"][self._g_ids]
        self._raw.update(
            c=pb["q"], A=self._a_eq, b=pb["l"][eq], G=self._g, h_l=pb["l"][~eq], h_u=pb["u"][~eq]
        )
        self._raw.solve()
        return 1e3 * (time.perf_counter() - start)


def _cvxpy_replay(problems: list[dict[str, Any]], solver: str) -> tuple[list[float], float]:
    """Per-step times [ms] of the same QPs in cvxpy with parameters, and the total [s] including
    problem construction and compilation (the first solve)."""
    import cvxpy as cp

    total_start = time.perf_counter()
    times: list[float] = []
    model: dict[str, Any] = {}
    for pb in problems:
        if pb["setup"] or not model:
            a = pb["A"].tocoo()
            nnz, (m, nv) = a.nnz, a.shape
            z = cp.Variable(nv)
            v, q = cp.Parameter(nnz), cp.Parameter(nv)
            lo, hi = cp.Parameter(m), cp.Parameter(m)
            pick = sp.csr_matrix((np.ones(nnz), (np.arange(nnz), a.col)), shape=(nnz, nv))
            rows = sp.csr_matrix((np.ones(nnz), (a.row, np.arange(nnz))), shape=(m, nnz))
            pfull = (pb["P"] + sp.triu(pb["P"], 1).T).tocsc()
            az = rows @ cp.multiply(v, pick @ z)
            finite_lo, finite_hi = np.isfinite(pb["l"]), np.isfinite(pb["u"])
            cons = [cp.multiply(finite_lo, az) >= lo, cp.multiply(finite_hi, az) <= hi]
            problem = cp.Problem(cp.Minimize(0.5 * cp.quad_form(z, cp.psd_wrap(pfull)) + q @ z), cons)
            model = {"problem": problem, "v": v, "q": q, "lo": lo, "hi": hi, "coo_order": _coo_order(pb["A"])}
            model["finite"] = finite_lo, finite_hi
        start = time.perf_counter()
        finite_lo, finite_hi = model["finite"]
        model["v"].value = pb["Ax"][model["coo_order"]]
        model["q"].value = pb["q"]
        model["lo"].value = np.where(finite_lo, pb["l"], 0.0)
        model["hi"].value = np.where(finite_hi, pb["u"], 0.0)
        with warnings.catch_warnings():  # cvxpy warns of inaccurate solutions: timing only here
            warnings.simplefilter("ignore")
            model["problem"].solve(solver=solver.upper(), warm_start=True)
        times.append(1e3 * (time.perf_counter() - start))
    return times, time.perf_counter() - total_start


def _coo_order(a: sp.csc_matrix) -> Array:
    """Indices taking CSC data to the entry order of ``a.tocoo()``."""
    ids = a.copy()
    ids.data = np.arange(a.nnz, dtype=float)
    return ids.tocoo().data.astype(np.intp)


def _rollout_ms(planner: MPCPlanner, t: float, p0: Array) -> float:
    st = planner.settings
    start = time.perf_counter()
    targets, ff = feedforward_targets(planner.reference, t, planner.dt_s, st.horizon, st.feedforward)
    x = p0
    for j in range(st.horizon):
        x = x + planner.dt_s * (ff[j] + st.gain_per_s * (targets[j] - x))
    return 1e3 * (time.perf_counter() - start)


def bench_case(
    n: int, dim: int, steps: int, solver: str, coupling: str, cvxpy_solver: str | None
) -> dict[str, Any]:
    """One swap: our step times by mode, the raw-solver, rollout and (optionally) cvxpy references."""
    ref, p = swap_case(n, dim)
    settings = mode_settings(coupling, 10)
    limits = Limits(v_max_mps=1.0, d_min_m=0.5)
    options = SolverOptions(settings.eps_abs, settings.eps_rel, settings.max_iter, settings.time_limit_s)
    rec = RecordingBackend(make_backend(solver, options))
    per_drone = settings.solves_per_drone  # then --solver is cvxpy's only
    planner = MPCPlanner(ref, 0.1, limits, settings, solver=DEFAULT_SOLVER if per_drone else rec)
    planner.reset(0.0, p)
    ours: dict[str, list[float]] = {"qp": [], "fast_path": [], "fallback": []}
    rollout: list[float] = []
    raw_solver, raw, ratios = _RawSolver(solver, options), [], []  # raw replay right after each QP step
    whole = 0.0
    for j in range(steps):
        t, recorded = 0.1 * j, len(rec.problems)
        start = time.perf_counter()
        out = planner.step(t, p)
        elapsed = 1e3 * (time.perf_counter() - start)
        whole += elapsed / 1e3
        ours[out.info.mode].append(elapsed)
        if out.info.mode == "fast_path":
            rollout.append(_rollout_ms(planner, t, p))
        if per_drone and out.info.mode == "qp":  # the same per-drone QPs in bare DAQP calls
            raw.append(1e3 * out.info.solve_time_s)
            ratios.append(elapsed / raw[-1])
        if len(rec.problems) > recorded:
            raw_ms = raw_solver.run(rec.problems[-1])
            if raw_ms is not None and out.info.mode == "qp":
                raw.append(raw_ms)
                ratios.append(elapsed / raw_ms)
        p = p + 0.1 * out.command_mps
    setup_steps = [i for i, pb in enumerate(rec.problems) if pb["setup"]]
    row: dict[str, Any] = {
        "case": f"swap {'planar' if dim == 2 else 'spatial'}", "n": n, "dim": dim, "steps": steps,
        "solver": planner.solver_name, "coupling": coupling, "qp_steps": len(ours["qp"]),
        "fast_path_steps": len(ours["fast_path"]), "fallback_steps": len(ours["fallback"]),
        "rebuilds": len(setup_steps),
    }  # fmt: skip
    row["qp_ms_median"], row["qp_ms_p90"] = median_p90(ours["qp"])
    row["raw_ms_median"], row["raw_ms_p90"] = median_p90(raw)
    row["overhead"] = median_p90(ratios)[0]  # median of paired per-step ratios (same load)
    row["fast_ms_median"], row["fast_ms_p90"] = median_p90(ours["fast_path"])
    row["rollout_ms_median"] = median_p90(rollout)[0]
    row["fast_ratio"] = row["fast_ms_median"] / row["rollout_ms_median"] if rollout else float("nan")
    row["whole_s"] = whole
    if cvxpy_solver is not None:
        full = RecordingBackend(make_backend(solver, options))  # every step as a QP, as cvxpy users solve
        sparse = replace(settings, fast_path=False, per_drone=False)
        no_fast = MPCPlanner(ref, 0.1, limits, sparse, solver=full)  # per drone: the same QPs, one sparse QP
        q = swap_case(n, dim)[1]
        no_fast.reset(0.0, q)
        for j in range(steps):
            q = q + 0.1 * no_fast.step(0.1 * j, q).command_mps
        cv_times, cv_total = _cvxpy_replay(full.problems, cvxpy_solver)
        row["cvxpy_ms_median"], row["cvxpy_ms_p90"] = median_p90(cv_times[1:])
        row["cvxpy_speedup_qp"] = row["cvxpy_ms_median"] / row["qp_ms_median"]
        row["cvxpy_whole_s"] = cv_total
        row["cvxpy_speedup_whole"] = cv_total / whole
    return row


COLUMNS = [
    ("case", "case", "{}"), ("n", "n", "{}"), ("steps", "steps", "{}"), ("qp_steps", "QP", "{}"),
    ("fast_path_steps", "fast", "{}"), ("qp_ms_median", "QP med [ms]", "{:.2f}"),
    ("qp_ms_p90", "QP p90", "{:.2f}"),
    ("raw_ms_median", "raw med", "{:.2f}"), ("overhead", "ours/raw", "{:.2f}x"),
    ("fast_ms_median", "fast med [ms]", "{:.3f}"), ("fast_ms_p90", "fast p90", "{:.3f}"),
    ("rollout_ms_median", "numpy rollout", "{:.3f}"), ("fast_ratio", "fast/rollout", "{:.1f}x"),
    ("cvxpy_ms_median", "cvxpy QP med", "{:.1f}"), ("cvxpy_speedup_qp", "vs cvxpy (QP)", "{:.1f}x"),
    ("whole_s", "whole [s]", "{:.2f}"), ("cvxpy_whole_s", "cvxpy whole", "{:.2f}"),
    ("cvxpy_speedup_whole", "vs cvxpy (whole)", "{:.1f}x"),
]  # fmt: skip


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a markdown table (missing or NaN entries shown as ``-``)."""
    return tables.markdown_table(rows, COLUMNS)


def run(
    planar_n: list[int], spatial_n: list[int], steps: int, solver: str, coupling: str, cvxpy_max_n: int
) -> list[dict[str, Any]]:
    """All cases; cvxpy only up to ``cvxpy_max_n`` drones (its compilation grows quickly)."""
    cvxpy_solver = solver if _have_cvxpy() else None
    rows = []
    for dim, sizes in ((2, planar_n), (3, spatial_n)):
        for n in sizes:
            rows.append(
                bench_case(n, dim, steps, solver, coupling, cvxpy_solver if n <= cvxpy_max_n else None)
            )
    return rows


def _have_cvxpy() -> bool:
    try:
        import cvxpy  # noqa: F401
    except ImportError:
        return False
    return True
