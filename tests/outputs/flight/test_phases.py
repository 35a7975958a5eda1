"""The whole flight, ground to ground (mpcform.outputs.flight.phases)."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.formation.geometry import min_pair_distances, min_segment_distance
from mpcform.formation.template import Template
from mpcform.outputs.flight import phases
from mpcform.outputs.flight.limits import FlightLimits
from mpcform.world.limits import Limits

LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5, tracking_m=0.05)


def test_the_septic_legs_peaks_match_finite_differences() -> None:
    s = np.linspace(0.0, 1.0, 4001)
    p = 35 * s**4 - 84 * s**5 + 70 * s**6 - 20 * s**7
    assert p[0] == 0.0 and p[-1] == pytest.approx(1.0)
    h = s[1] - s[0]
    for r, peak in enumerate(phases.LEG_PEAKS, start=1):
        d = p
        for _ in range(r):
            d = np.diff(d) / h
        assert np.abs(d).max() == pytest.approx(peak, rel=5e-3)
    assert phases.LEG_PEAKS[0] == pytest.approx(35 / 16)


@pytest.mark.parametrize("height", [0.3, 3.0, 12.0])
def test_a_vertical_leg_keeps_the_limits(height: float) -> None:
    lim = FlightLimits()
    t = phases.vertical_leg_s(height, lim)
    peaks = [p * height / t**r for r, p in enumerate(phases.LEG_PEAKS, start=1)]
    bounds = [0.9 * lim.max_speed_mps, 0.9 * lim.max_acc_mps2, 0.9 * lim.max_jerk_mps3]
    assert all(p <= b * (1 + 1e-12) for p, b in zip(peaks, bounds, strict=True))
    assert t == phases.LEG_MIN_S or any(p == pytest.approx(b) for p, b in zip(peaks, bounds, strict=True))


def test_a_spread_start_takes_off_below_itself_a_stacked_one_from_a_grid() -> None:
    ring = Template.polygon(8, 3.0).offsets
    np.testing.assert_array_equal(phases.ground_layout(ring, 0.75), ring)
    stacked = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [3.0, 3.0], [3.05, 3.0]])  # two towers
    grid = phases.ground_layout(stacked, 0.75)
    assert min_pair_distances(grid[None])[0] >= 0.75 - 1e-12
    cells = np.round((grid - grid.min(axis=0)) / 0.75, 9)
    assert np.all(cells == np.round(cells))  # on a grid of that spacing
    from scipy.optimize import linear_sum_assignment

    side = 3  # ceil(sqrt(5)) cells a side: the assignment is the cheapest of all
    points = 0.75 * np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)
    points += stacked.mean(axis=0) - points.mean(axis=0)
    cost = ((stacked[:, None] - points[None]) ** 2).sum(-1)
    rows, cols = linear_sum_assignment(cost)
    assert ((grid - stacked) ** 2).sum() == pytest.approx(cost[rows, cols].sum())


def test_a_phase_reaches_its_goal_apart_and_within_v_max() -> None:
    goal = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.6], [0.3, 0.0, 2.2], [1.0, 0.5, 1.2]])  # a tower
    start = np.column_stack([phases.ground_layout(goal[:, :2], 0.75), np.full(4, 0.3)])
    path = phases.plan_phase(start, goal, 0.1, LIMITS, "ascent")
    np.testing.assert_array_equal(path[0], start)
    np.testing.assert_array_equal(path[-1], goal)
    seg = min(min_segment_distance(a, b) for a, b in zip(path[:-2], path[1:-1], strict=True))
    assert seg >= 0.5 + 2 * 0.05 - 1e-6  # d_min and the tracking allowance, as the planner keeps them
    steps = np.linalg.norm(np.diff(path, axis=0), axis=-1)
    assert steps.max() <= 0.1 * 1.0 + 1e-9
    # the gap left at arrival (up to 2 mm) is closed over the last second, not in one last jump
    assert np.all(steps[-1] <= steps[-2])
    assert phases.plan_phase(goal, goal, 0.1, LIMITS, "ascent").shape == (1, 4, 3)  # no motion


def test_a_phase_that_cannot_arrive_is_refused() -> None:
    goal = np.array([[0.0, 0.0, 1.0], [0.3, 0.0, 1.0]])  # closer than d_min: never both reached
    start = np.array([[-2.0, 0.0, 0.3], [2.0, 0.0, 0.3]])
    with pytest.raises(ValidationError, match="flight: the planned ascent left drone"):
        phases.plan_phase(start, goal, 0.1, LIMITS, "ascent")


def test_the_whole_flight_joins_its_phases() -> None:
    t = np.linspace(0.0, 1.0, 11)[:, None, None]
    mission = np.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0]]) + t * np.array([1.0, 0.0, 0.0])
    flight = phases.whole_flight(mission, 0.1, LIMITS, FlightLimits(), floor_m=0.2)
    names = [name for name, _ in flight.phases]
    assert names == ["ascent", "mission", "descent"]
    parts = dict(flight.phases)
    np.testing.assert_array_equal(flight.positions_m[parts["mission"]], mission)
    assert flight.positions_m[0, :, 2].tolist() == [0.5, 0.5] and flight.hover_m == 0.5
    np.testing.assert_array_equal(flight.takeoff_xy_m, mission[0, :, :2])
    np.testing.assert_array_equal(flight.positions_m[-1, :, :2], flight.landing_xy_m)
    assert (
        parts["ascent"].stop - 1 == parts["mission"].start
        and parts["mission"].stop - 1 == parts["descent"].start
    )
    assert flight.takeoff_s == flight.land_s == phases.LEG_MIN_S


def test_given_pads_are_assigned_nearest_and_refused_when_too_few_or_too_close() -> None:
    xy = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    pads = np.array([[4.1, 1.0], [9.0, 9.0], [-0.1, 1.0], [2.0, 1.0]])
    np.testing.assert_array_equal(phases.pad_layout(xy, pads, 1.0), [2, 3, 0])  # the far pad unused
    with pytest.raises(ValidationError, match=r"^ground: 2 pads on the floor for 3 drones"):
        phases.pad_layout(xy, pads[:2], 1.0)
    close = np.array([[0.0, 0.0], [0.3, 0.0], [4.0, 0.0]])
    with pytest.raises(
        ValidationError, match=r"^ground: pads 0 and 1 are 0.3 m apart, closer than the 0.6 m"
    ):
        phases.pad_layout(xy, close, 0.6)
    t = np.linspace(0.0, 1.0, 11)[:, None, None]
    mission = np.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0]]) + t * np.array([1.0, 0.0, 0.0])
    flight = phases.whole_flight(mission, 0.1, LIMITS, FlightLimits(), pads_m=pads)
    np.testing.assert_array_equal(flight.takeoff_xy_m, pads[[2, 3]])
    np.testing.assert_array_equal(flight.landing_xy_m, pads[[3, 0]])  # landing nearest the last positions
    np.testing.assert_array_equal(flight.positions_m[0, :, :2], pads[[2, 3]])
