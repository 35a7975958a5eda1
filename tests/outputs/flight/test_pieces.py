"""One phase as flyable pieces (mpcform.outputs.flight.pieces)."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.outputs.flight import pieces
from mpcform.outputs.flight.limits import FlightLimits, flat_state


def _phase(name: str, start: float, length: float) -> pieces.PhasePieces:
    """Two drones flying ``length`` m along x (planned as a ramp at 0.5 m/s every 0.1 s)."""
    t = np.arange(0.0, 2.0 * length + 1e-9, 0.1)
    x = start + np.minimum(0.5 * t, length)
    planned = np.stack([np.column_stack([x, y + 0 * x, 1.0 + 0 * x]) for y in (0.0, 1.0)], axis=1)
    yaw = np.linspace(0.0, 0.3, t.shape[0])
    return pieces.phase_pieces(name, planned, 0.1, yaw, FlightLimits(), 0.02, 2.0, 100.0)


def test_a_phase_is_rest_to_rest_within_its_tolerance_and_limits() -> None:
    part = _phase("mission", 0.0, 3.0)
    poly = part.flown
    ends = np.array([0.0, poly.duration_s])
    for r in (1, 2, 3):  # at rest at both ends, up to the jerk
        assert np.abs(poly.evaluate(ends, r)).max() < 1e-4  # float32 coefficients
    assert part.fit.max_error_m <= 0.02 and part.fit.within_tolerance
    at = poly.evaluate(part.t_planned_s).reshape(-1, 2, 4)
    np.testing.assert_allclose(at[..., :3], part.planned_m, atol=0.02)  # every planned sample
    np.testing.assert_allclose(at[-1, 0, 3], 0.3, atol=1e-6)  # the yaw rides along
    t = np.linspace(0.0, poly.duration_s, 4001)
    state = flat_state(poly, t, 2)
    assert np.linalg.norm(state["vel"], axis=-1).max() <= FlightLimits().max_speed_mps
    assert np.linalg.norm(state["acc"], axis=-1).max() <= FlightLimits().max_acc_mps2
    assert part.dense_m.shape == (pieces.PATH_SAMPLES * (part.planned_m.shape[0] - 1) + 1, 2, 3)


def test_phases_join_at_rest() -> None:
    a, b = _phase("ascent", 0.0, 1.0), _phase("mission", 1.0, 2.0)
    whole = pieces.join([a, b])
    assert whole.duration_s == pytest.approx(a.flown.duration_s + b.flown.duration_s)
    seam = a.flown.duration_s
    left, right = whole.evaluate(np.array([seam - 1e-9, seam + 1e-9])).reshape(2, 2, 4)
    np.testing.assert_allclose(left[..., :3], right[..., :3], atol=1e-6)
    assert np.abs(whole.evaluate(np.array([seam]), 1)).max() < 1e-4


def test_too_many_samples_are_refused_naming_the_rate() -> None:
    with pytest.raises(ValidationError, match="rate: the export would take"):
        pieces.check_samples(1e4, 1000, 100.0)
    pieces.check_samples(10.0, 2, 100.0)


def test_a_smoother_timing_is_kept_only_when_it_fits_in_a_crazyflie(monkeypatch: pytest.MonkeyPatch) -> None:
    fast = _phase("mission", 0.0, 3.0)
    monkeypatch.setattr(pieces, "CRAZYFLIE_MAX_PIECES", (fast.flown.pieces + 1) // 2)  # no share gets there
    kept = _phase("mission", 0.0, 3.0)
    assert kept.flown.pieces == fast.flown.pieces
    assert kept.timing.duration_s == pytest.approx(fast.timing.duration_s, rel=1e-12)


def test_the_timing_is_the_one_the_pieces_were_fitted_to_when_the_refits_run_out(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(pieces, "LIMIT_SLACK", 1.5)  # aim above the limits: every fit exceeds one
    monkeypatch.setattr(pieces, "REFITS", 1)
    part = _phase("mission", 0.0, 3.0)
    assert part.timing.duration_s == pytest.approx(part.flown.duration_s, abs=1e-4)
