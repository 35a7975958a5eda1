"""Summary statistics of timings: median and p90, shifted geometric mean."""

from __future__ import annotations

import math

import pytest

from mpcform.bench.stats import median_p90, shifted_geometric_mean


def test_shifted_geometric_mean() -> None:
    assert shifted_geometric_mean([2e-3] * 4) == pytest.approx(2e-3)
    assert shifted_geometric_mean([0.0, 1e-4], shift=1e-4) == pytest.approx((1e-4 * 2e-4) ** 0.5 - 1e-4)
    # the shift damps the tiny outliers: 1 us and 1 ms average to about 0.3 ms, not 32 us
    assert 2e-4 < shifted_geometric_mean([1e-6, 1e-3]) < 4e-4


def test_median_p90() -> None:
    assert median_p90([3.0, 1.0, 2.0]) == (2.0, pytest.approx(2.8))
    assert median_p90([float(i) for i in range(11)]) == (5.0, 9.0)
    assert all(math.isnan(v) for v in median_p90([]))
