"""The floors ``bench mpc`` measures the planner against, each timed in wall and CPU time.

- :class:`RawReplay`: the recorded QPs on a bare persistent solver object (``osqp.OSQP`` or
  ``piqp.SparseSolver``, the same settings as ours), set up once per sparsity pattern and updated
  otherwise, like our backend: a step's raw time includes a setup where ours has one;
- :func:`daqp_meter`: the time spent in ``daqp.solve`` (the bare DAQP calls of a per-drone step);
- :func:`rollout_ms`: eq. 14 rolled out over the horizon in plain numpy (reference targets included);
- :func:`cvxpy_replay`: the same QPs written in cvxpy with parameters, solved by the same solver,
  within a time budget extrapolated from its first solves.

Times are pairs ``(wall, CPU)`` [ms]; CPU time is the process's (``time.process_time``), which a
loaded machine does not inflate the way it inflates wall time.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.control.base import feedforward_targets
from mpcform.mpc.planner import MPCPlanner
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.persistent import pattern_key, row_split

Times = tuple[float, float]
"""``(wall, CPU)`` [ms]."""


@dataclass
class Stopwatch:
    """Wall and CPU time from its creation."""

    wall_s: float = field(default_factory=time.perf_counter)
    cpu_s: float = field(default_factory=time.process_time)

    def ms(self) -> Times:
        """Elapsed ``(wall, CPU)`` [ms]."""
        return 1e3 * (time.perf_counter() - self.wall_s), 1e3 * (time.process_time() - self.cpu_s)


def added(a: Times, b: Times) -> Times:
    return a[0] + b[0], a[1] + b[1]


class RawReplay:
    """A bare persistent solver object per sparsity pattern, fed the recorded QPs one by one."""

    def __init__(self, solver: str, options: SolverOptions) -> None:
        self.solver, self.options = solver, options
        self._objects: dict[bytes, dict[str, Any]] = {}
        self._current: dict[str, Any] = {}
        self.x: Array = np.empty(0)  # the last solution

    def run(self, pb: dict[str, Any]) -> Times:
        """Set up (a pattern not seen yet) or update, then solve: the time of it all. The solution
        is then in :attr:`x`."""
        clock = Stopwatch()
        key = pattern_key(pb["P"], pb["A"], pb["l"] == pb["u"]) if pb["setup"] else b""
        if key and key not in self._objects:
            self._objects[key] = self._setup(pb)
        else:
            self._current = self._objects[key] if key else self._current
            self._update(pb)
        took = clock.ms()
        raw = self._current["raw"]
        self.x = np.array(raw.result.x if self.solver == "piqp" else self._current["res"].x)
        return took

    @property
    def objects(self) -> int:
        """Solver objects set up so far (one per pattern)."""
        return len(self._objects)

    def _setup(self, pb: dict[str, Any]) -> dict[str, Any]:
        o = self.options
        if self.solver == "osqp":
            import osqp

            raw = osqp.OSQP()
            raw.setup(pb["P"], pb["q"], pb["A"], pb["l"], pb["u"], verbose=False, eps_abs=o.eps_abs,
                      eps_rel=o.eps_rel, max_iter=o.max_iter, polishing=True)  # fmt: skip
            self._current = {"raw": raw, "res": raw.solve(raise_error=False)}
            return self._current
        import piqp

        eq = pb["l"] == pb["u"]
        (a_eq, eq_ids), (g, g_ids) = row_split(pb["A"], eq), row_split(pb["A"], ~eq)
        a_eq.data, g.data = pb["Ax"][eq_ids], pb["Ax"][g_ids]
        raw = piqp.SparseSolver()
        raw.settings.verbose = False
        raw.settings.eps_abs, raw.settings.eps_rel = o.eps_abs, o.eps_rel
        raw.setup(pb["P"], pb["q"], a_eq, pb["l"][eq], g, pb["l"][~eq], pb["u"][~eq])
        raw.solve()
        self._current = {"raw": raw, "eq": eq, "a_eq": a_eq, "eq_ids": eq_ids, "g": g, "g_ids": g_ids}
        return self._current

    def _update(self, pb: dict[str, Any]) -> None:
        cur, raw = self._current, self._current["raw"]
        if self.solver == "osqp":
            raw.update(q=pb["q"], l=pb["l"], u=pb["u"], Ax=pb["Ax"])
            cur["res"] = raw.solve(raise_error=False)
            return
        eq = cur["eq"]
        cur["a_eq"].data, cur["g"].data = pb["Ax"][cur["eq_ids"]], pb["Ax"][cur["g_ids"]]
        raw.update(c=pb["q"], A=cur["a_eq"], b=pb["l"][eq], G=cur["g"], h_l=pb["l"][~eq], h_u=pb["u"][~eq])
        raw.solve()


@contextmanager
def daqp_meter() -> Iterator[list[float]]:
    """``[wall, CPU]`` [ms] spent in ``daqp.solve`` while open: the bare DAQP calls of per-drone
    steps. The timing wrapper adds about a microsecond per call to the step it measures."""
    import daqp

    inner, spent = daqp.solve, [0.0, 0.0]

    def timed(*args: Any, **kwargs: Any) -> Any:
        clock = Stopwatch()
        try:
            return inner(*args, **kwargs)
        finally:
            wall, cpu = clock.ms()
            spent[0] += wall
            spent[1] += cpu

    daqp.solve = timed
    try:
        yield spent
    finally:
        daqp.solve = inner


def rollout_ms(planner: MPCPlanner, t: float, p0: Array) -> Times:
    """Time of eq. 14 rolled out over the planner's horizon from ``p0`` in plain numpy."""
    st = planner.settings
    clock = Stopwatch()
    targets, ff = feedforward_targets(planner.reference, t, planner.dt_s, st.horizon, st.feedforward)
    x = p0
    for j in range(st.horizon):
        x = x + planner.dt_s * (ff[j] + st.gain_per_s * (targets[j] - x))
    return clock.ms()


@dataclass
class CvxpyResult:
    """Solve times of the QPs that kept the previous QP's pattern (parameter values set + solve),
    the whole replay's time (problem construction and compilation included), or why it stopped."""

    times: list[Times] = field(default_factory=list)
    whole: Times = (0.0, 0.0)
    skipped: str = ""


def cvxpy_replay(problems: list[dict[str, Any]], solver: str, budget_s: float) -> CvxpyResult:
    """The recorded QPs through cvxpy, unless the wall time extrapolated from the first two
    exceeds ``budget_s`` [s]: each new pattern costs what the first QP did (construction and
    compilation included), each other QP what the second did. Then it stops with the reason."""
    out, model = CvxpyResult(), _CvxpyModel(solver)
    setups = sum(1 for pb in problems if pb["setup"]) or 1
    first_ms = 0.0
    for i, pb in enumerate(problems):
        clock, new = Stopwatch(), pb["setup"] or i == 0
        if new:
            model.build(pb)
        solve = model.solve(pb)
        out.whole = added(out.whole, clock.ms())
        if not new:
            out.times.append(solve)
        if i == 0:
            first_ms = out.whole[0]
        if i <= 1:
            rest_ms = solve[0] if i else 0.0
            estimate_s = (setups * first_ms + (len(problems) - setups) * rest_ms) / 1e3
            if estimate_s > budget_s:
                out.skipped = (f"estimated {estimate_s:.0f} s > budget {budget_s:g} s ({len(problems)} QPs, "
                               f"{setups} patterns: the first {first_ms / 1e3:.1f} s with its compilation"
                               + (f", then {rest_ms:.0f} ms per QP)" if i else ")"))  # fmt: skip
                return out
    return out


class _CvxpyModel:
    """The QP in cvxpy with parameters: cost vector, bounds, and the values of A written as
    ``A(v) z = R (v * (C z))`` with constant selections R and C."""

    def __init__(self, solver: str) -> None:
        self.solver = solver.upper()
        self._m: dict[str, Any] = {}

    def build(self, pb: dict[str, Any]) -> None:
        import cvxpy as cp

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
        self._m = {"problem": problem, "v": v, "q": q, "lo": lo, "hi": hi, "coo_order": coo_order(pb["A"]),
                   "finite": (finite_lo, finite_hi)}  # fmt: skip

    def solve(self, pb: dict[str, Any]) -> Times:
        m, clock = self._m, Stopwatch()
        finite_lo, finite_hi = m["finite"]
        m["v"].value = pb["Ax"][m["coo_order"]]
        m["q"].value = pb["q"]
        m["lo"].value = np.where(finite_lo, pb["l"], 0.0)
        m["hi"].value = np.where(finite_hi, pb["u"], 0.0)
        with warnings.catch_warnings():  # cvxpy warns of inaccurate solutions: timing only here
            warnings.simplefilter("ignore")
            m["problem"].solve(solver=self.solver, warm_start=True)
        return clock.ms()


def coo_order(a: sp.csc_matrix) -> Array:
    """Indices taking CSC data to the entry order of ``a.tocoo()``."""
    ids = a.copy()
    ids.data = np.arange(a.nnz, dtype=float)
    return ids.tocoo().data.astype(np.intp)
