"""Summary statistics of timings: median and p90, shifted geometric mean."""

from __future__ import annotations

import math

import pytest

from mpcform.bench.stats import median_p90, p50_p99_max, shifted_geometric_mean, solver_floor


def test_shifted_geometric_mean() -> None:
    assert shifted_geometric_mean([2e-3] * 4) == pytest.approx(2e-3)
    assert shifted_geometric_mean([0.0, 1e-4], shift=1e-4) == pytest.approx((1e-4 * 2e-4) ** 0.5 - 1e-4)
    # the shift damps the tiny outliers: 1 us and 1 ms average to about 0.3 ms, not 32 us
    assert 2e-4 < shifted_geometric_mean([1e-6, 1e-3]) < 4e-4


def test_median_p90() -> None:
    assert median_p90([3.0, 1.0, 2.0]) == (2.0, pytest.approx(2.8))
    assert median_p90([float(i) for i in range(11)]) == (5.0, 9.0)
    assert all(math.isnan(v) for v in median_p90([]))


def test_p50_p99_max() -> None:
    values = [float(i) for i in range(101)]
    assert p50_p99_max(values) == (50.0, 99.0, 100.0)
    p50, p99, top = p50_p99_max([4.0, 1.0, 9.0])
    assert p50 == 4.0 and p50 <= p99 <= top == 9.0
    assert all(math.isnan(v) for v in p50_p99_max([]))


def test_solver_floor_is_the_ratio_of_the_medians_of_the_steps_that_called_the_solver() -> None:
    floor = solver_floor([10.0, 30.0, 20.0, 1.0], [5.0, 6.0, 1.0, 0.0])  # the last: no solver call
    assert (floor.steps, floor.step_ms_median, floor.solver_ms_median, floor.ratio) == (3, 20.0, 5.0, 4.0)
    assert solver_floor([], []).steps == 0 and math.isnan(solver_floor([], []).ratio)
    assert math.isnan(solver_floor([2.0], [0.0]).ratio)
    with pytest.raises(ValueError, match="2 step times for 1"):
        solver_floor([1.0, 2.0], [1.0])
