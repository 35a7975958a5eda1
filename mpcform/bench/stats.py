"""Summary statistics of benchmark timings: median and 90th or 99th percentile, shifted geometric
mean, and a step time against the solver's share of it (:class:`SolverFloor`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

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


def p50_p99_max(values: Sequence[float]) -> tuple[float, float, float]:
    """Median, 99th percentile and maximum of ``values`` (NaN each when there are none)."""
    if not values:
        return math.nan, math.nan, math.nan
    return float(np.median(values)), float(np.percentile(values, 99)), float(np.max(values))


@dataclass(frozen=True)
class SolverFloor:
    """The steps that called the solver (their time in its calls positive) against the time in
    those calls, the bare solver floor: how many, their median step and median solver time [ms],
    and the ``ratio`` of the two (NaN without such steps). Each step contains its solver calls, so
    the ratio is >= 1."""

    steps: int
    step_ms_median: float
    solver_ms_median: float

    @property
    def ratio(self) -> float:
        """Median step / median solver time (NaN without steps that called the solver)."""
        return self.step_ms_median / self.solver_ms_median if self.steps else math.nan


def solver_floor(step_ms: Sequence[float], solver_ms: Sequence[float]) -> SolverFloor:
    """The :class:`SolverFloor` of steps timed ``step_ms`` [ms] that spent ``solver_ms`` [ms] in
    the solver's calls, step by step (zero: no call, such as a fast-path step; left out)."""
    if len(step_ms) != len(solver_ms):
        raise ValueError(f"{len(step_ms)} step times for {len(solver_ms)} solver times")
    called = [(t, s) for t, s in zip(step_ms, solver_ms, strict=True) if s > 0]
    if not called:
        return SolverFloor(0, math.nan, math.nan)
    step, solver = zip(*called, strict=True)
    return SolverFloor(len(called), float(np.median(step)), float(np.median(solver)))


def shifted_geometric_mean(values: Sequence[float], shift: float = SHIFT_S) -> float:
    """``exp(mean(log(v + shift))) - shift`` of nonnegative values."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return math.nan
    return float(np.exp(np.mean(np.log(v + shift))) - shift)
