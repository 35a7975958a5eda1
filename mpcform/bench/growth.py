"""Growth exponents of ``mpcform bench scale``: how a step time grows with the number of drones.

A time growing as ``t ~ n^e`` has exponent ``e``: fitted by least squares on ``log t`` against
``log n`` over the larger sizes, and read off two sizes (100 and 1000 drones).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

GROWTH_MIN_N = 100  # exponents are fitted over n >= this


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
        rec: dict[str, Any] = {
            "table": "growth",
            "scenario": scenario,
            "mode": mode,
            "sizes": ns,
            "partial": [r["n"] for r in case if r["steps_run"] < r["steps"]],
        }
        for key, name in (("step_ms_median", "step"), ("qp_ms_median", "qp")):
            t = [r.get(key, float("nan")) for r in case]
            rec[f"{name}_exponent_fit"] = growth_exponent(ns, t)
            rec[f"{name}_exponent_100_1000"] = two_point_exponent(ns, t)
        out.append(rec)
    return out
