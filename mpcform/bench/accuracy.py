"""Accuracy settings and the success rule of ``mpcform bench solvers`` (conventions of qpbenchmark).

Four accuracy settings: ``default`` (the solver's own settings) and ``low`` / ``mid`` / ``high``
(``eps_abs`` 1e-3 / 1e-6 / 1e-9, ``eps_rel`` 0, mapped to each solver's parameters). A solve
*succeeds* when it is found within the time limit with primal residual ``<= tol`` and objective
gap ``|f - f*| / max(1, |f*|) <= tol``, ``tol`` = 1e-3 for default and low, 1e-6 for mid, 1e-9 for
high; ``f*`` is the same QP solved by clarabel at 1e-9 (``eps_rel`` 0). ``casadi:ipopt`` solves
the exact non-convex problem instead: it is judged on its exact residual, not on the gap (its
objective is below the QP's, and the difference is the price of the linearisation).

Runtimes are summarised per (solver, mode, setting) by their shifted geometric mean
(:mod:`mpcform.bench.stats`), counting failures at the time limit (qpbenchmark's rule); medians
and p90s are over successful solves.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from mpcform.bench.problems import RecordedQP
from mpcform.bench.stats import shifted_geometric_mean
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import solver_names

SETTINGS: dict[str, float | None] = {"default": None, "low": 1e-3, "mid": 1e-6, "high": 1e-9}
"""Accuracy settings: eps_abs given to the solver (None: the solver's defaults); eps_rel is 0."""
TOLERANCES = {"default": 1e-3, "low": 1e-3, "mid": 1e-6, "high": 1e-9}
"""Validation tolerance per setting, on the primal residual and the relative objective gap."""
REFERENCE_SOLVER = "qpsolvers:clarabel"
REFERENCE_EPS = 1e-9
"""The reference objective f* of a problem: REFERENCE_SOLVER at eps_abs REFERENCE_EPS, eps_rel 0."""
EXACT_SOLVER = "casadi:ipopt"
"""Solves the exact non-convex problem (true distance constraints), judged by its exact residual."""


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


def default_solvers() -> list[str]:
    """Every backend known here except the exact NLP (it is run separately)."""
    return [name for name in solver_names() if name != EXACT_SOLVER]


def objective_gap(objective: float | None, reference: float | None) -> float:
    """``(f - f*) / max(1, |f*|)`` (NaN when either is missing)."""
    if objective is None or reference is None:
        return math.nan
    return (objective - reference) / max(1.0, abs(reference))


def succeeded(res: dict[str, Any], reference: float | None, time_limit_s: float) -> bool:
    """Found within the time limit, primal residual and |objective gap| within the setting's tolerance."""
    tol = TOLERANCES[res["setting"]]
    if not res["found"] or res["runtime_s"] > time_limit_s or res["primal_residual"] > tol:
        return False
    return res["solver"] == EXACT_SOLVER or abs(objective_gap(res["objective"], reference)) <= tol


def summarize(
    results: Sequence[dict[str, Any]], references: Sequence[float | None], time_limit_s: float
) -> list[dict[str, Any]]:
    """One record per (solver, mode, setting): success rate, runtimes, residuals, objective gaps."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    rows: list[dict[str, Any]] = []
    for res in results:
        groups.setdefault((res["solver"], res["mode"], res["setting"]), []).append(res)
    for (solver, mode, setting), group in groups.items():
        ok = [succeeded(r, references[r["index"]], time_limit_s) for r in group]
        found = [r for r in group if r["found"]]
        good = [r for r, s in zip(group, ok, strict=True) if s]
        times = [r["runtime_s"] if r["found"] else time_limit_s for r in group]
        ms = [1e3 * r["runtime_s"] for r in good]
        gaps = [abs(objective_gap(r["objective"], references[r["index"]])) for r in found]
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
