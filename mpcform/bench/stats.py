"""Summary statistics of benchmark timings: median and 90th percentile, shifted geometric mean."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

SHIFT_S = 1e-4
"""Shift of the shifted geometric mean [s]: 0.1 ms, about the fastest solves of the problem set, so
that sub-millisecond noise does not dominate the ratios while a 10x slower solver still scores
about 10x."""


def median_p90(values: Sequence[float]) -> tuple[float, float]:
    """Median and 90th percentile of ``values`` (NaN, NaN when there are none)."""
    if not values:
        return float("nan"), float("nan")
    return float(np.median(values)), float(np.percentile(values, 90))


def shifted_geometric_mean(values: Sequence[float], shift: float = SHIFT_S) -> float:
    """``exp(mean(log(v + shift))) - shift`` of nonnegative values."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return math.nan
    return float(np.exp(np.mean(np.log(v + shift))) - shift)
