"""The floors ``bench mpc`` measures the planner against, each timed in wall and CPU time.

- :class:`RawReplay`: the recorded QPs on a bare persistent solver object (``osqp.OSQP`` or
  ``piqp.SparseSolver``, the same settings as ours), set up once per sparsity pattern and updated
  otherwise, like our backend: a step's raw time includes a setup where ours has one;
- :func:`daqp_meter`: the time spent in ``daqp.solve`` (the bare DAQP calls of a per-drone step);
- :func:`rollout_ms`: eq. 14 rolled out over the horizon in plain numpy (reference targets included);
- :func:`cvxpy_replay`: the same QPs written in cvxpy, solved by the same solver, within a time
  budget extrapolated from the first solves.

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
            raw.setup(
                pb["P"],
                pb["q"],
                pb["A"],
                pb["l"],
                pb["u"],
                verbose=False,
                eps_abs=o.eps_abs,
                eps_rel=o.eps_rel,
                max_iter=o.max_iter,
                polishing=True,
            )
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
    """Per-QP times (problem built and solved), their sum, or why the replay stopped."""

    times: list[Times] = field(default_factory=list)
    whole: Times = (0.0, 0.0)
    skipped: str = ""


def cvxpy_replay(problems: list[dict[str, Any]], solver: str, budget_s: float) -> CvxpyResult:
    """The recorded QPs through cvxpy, each built from its matrices as constants and solved by
    ``solver``, unless the wall time extrapolated from the first QPs exceeds ``budget_s`` [s]:
    then it stops after them with the reason.

    Built afresh every step rather than once with parameters (DPP): measured on these QPs, that is
    as fast at 8 drones and faster beyond (24 vs 38 ms at 16, 48 vs 79 ms at 32), and the
    parametrised form's compilation took 78 s at 64 planar drones and 163 s (15 GB) at 20 spatial."""
    out = CvxpyResult()
    for i, pb in enumerate(problems):
        took = cvxpy_solve(pb, solver)[0]
        out.times.append(took)
        out.whole = added(out.whole, took)
        if i <= 1:  # estimated from the second QP (the first may pay one-off costs) or a first one over
            estimate_s = (out.whole[0] + (len(problems) - i - 1) * took[0]) / 1e3
            last = i == min(1, len(problems) - 1)
            if estimate_s > budget_s and (last or out.whole[0] / 1e3 > budget_s):
                out.skipped = (
                    f"estimated {estimate_s:.3g} s > budget {budget_s:g} s ({len(problems)} QPs "
                    f"at {took[0] / 1e3:.2f} s)"
                )
                return out
    return out


def cvxpy_solve(pb: dict[str, Any], solver: str) -> tuple[Times, Array | None]:
    """Build the QP ``pb`` in cvxpy (equality, lower and upper rows apart, infinite bounds left
    out) and solve it: the time of both, and the solution (None if cvxpy has none)."""
    import cvxpy as cp

    clock = Stopwatch()
    a = pb["A"].copy()
    a.data = pb["Ax"]
    lo, hi = pb["l"], pb["u"]
    eq = lo == hi
    has_lo, has_hi = np.isfinite(lo) & ~eq, np.isfinite(hi) & ~eq
    z = cp.Variable(a.shape[1])
    p_full = (pb["P"] + sp.triu(pb["P"], 1).T).tocsc()
    cons = [a[eq] @ z == lo[eq], a[has_lo] @ z >= lo[has_lo], a[has_hi] @ z <= hi[has_hi]]
    problem = cp.Problem(cp.Minimize(0.5 * cp.quad_form(z, cp.psd_wrap(p_full)) + pb["q"] @ z), cons)
    with warnings.catch_warnings():  # cvxpy warns of inaccurate solutions: timing only here
        warnings.simplefilter("ignore")
        problem.solve(solver=solver.upper())
    return clock.ms(), z.value
