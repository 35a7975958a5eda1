"""Growth exponents: least-squares and two-point fits on synthetic power laws, per scenario and mode."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpcform.bench.growth import growth_exponent, growth_rows, two_point_exponent


def test_growth_exponent_fits_synthetic_power_laws() -> None:
    rng = np.random.default_rng(3)
    n = np.array([10, 30, 100, 300, 1000, 100, 300, 1000])
    t = 0.02 * n**1.3 * np.exp(rng.normal(0.0, 0.01, n.shape))
    t[:2] = 1e3  # points below n = 100 are ignored
    assert growth_exponent(n, t) == pytest.approx(1.3, abs=0.03)
    assert two_point_exponent([100, 1000], [5.0, 50.0]) == pytest.approx(1.0)
    assert two_point_exponent([100, 1000], [5.0, 5.0 * 10**1.2]) == pytest.approx(1.2)
    assert math.isnan(growth_exponent([10, 30, 100], [1.0, 2.0, 3.0]))  # one point at n >= 100
    assert math.isnan(two_point_exponent([100, 300], [1.0, 2.0]))
    assert math.isnan(growth_exponent([100, 1000], [1.0, float("nan")]))


def test_growth_rows_per_scenario_and_mode() -> None:
    rows = [
        {
            "scenario": "crossing",
            "mode": "decoupled",
            "n": n,
            "steps": 10,
            "steps_run": 10,
            "step_ms_median": 0.1 * n,
            "qp_ms_median": 0.01 * n**1.5,
        }
        for n in (100, 300, 1000)
    ]
    rows[-1]["steps_run"] = 4
    (g,) = growth_rows(rows)
    assert g["step_exponent_fit"] == pytest.approx(1.0) and g["step_exponent_100_1000"] == pytest.approx(1.0)
    assert g["qp_exponent_fit"] == pytest.approx(1.5) and g["partial"] == [1000]
