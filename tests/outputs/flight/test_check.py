"""Flying an export on the quadrotor plant: true error within plant margin + fit tolerance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from saved_runs import short_run

from mpcform.outputs.flight.check import drone_models_available, fly_export
from mpcform.outputs.flight.export import export_run
from mpcform.outputs.flight.polynomial import PiecewisePolynomial
from mpcform.outputs.rundata import load_run

needs_drone_models = pytest.mark.skipif(not drone_models_available(), reason="needs drone-models")


@needs_drone_models
def test_hover_is_flown_in_place() -> None:
    coef = np.zeros((2, 8, 8))
    coef[:, 0::4, 0] = [0.0, 1.0]  # x = 0 / 1, y = 0, z = 0 ... per drone x, y, z, yaw
    coef[:, 2, 0] = coef[:, 6, 0] = 1.5
    coef[:, 4, 0] = 1.0
    poly = PiecewisePolynomial(0.0, np.array([1.0, 1.0]), coef)
    check = fly_export(poly, 2, 0.02, 0.1, 3.0)
    assert check is not None and check.max_error_m < 1e-3
    assert check.min_separation_m == pytest.approx(1.0, abs=1e-3) and check.within_tolerance


@needs_drone_models
def test_export_records_the_flown_swarm(tmp_path: Path) -> None:
    short_run("swap_planar_8", tmp_path / "run", steps=60, flyable=True)
    result = export_run(load_run(tmp_path / "run"), tmp_path / "export")
    flight = result.record["quadrotor_flight"]
    assert flight is not None and flight["within_tolerance"]
    assert flight["declared_tolerance_m"] == pytest.approx(flight["plant_margin_m"] + 0.02)
    assert 0.0 < flight["max_tracking_error_m"] <= flight["declared_tolerance_m"]
    assert flight["min_separation_m"] > 0.0


def test_skipped_without_drone_models(monkeypatch: pytest.MonkeyPatch) -> None:
    from mpcform.outputs.flight import check as flight_check

    monkeypatch.setattr(flight_check, "drone_models_available", lambda: False)
    poly = PiecewisePolynomial(0.0, np.array([1.0]), np.zeros((1, 4, 8)))
    assert flight_check.fly_export(poly, 1, 0.02, 0.1, 3.0) is None
