"""What an export refuses: the closest pair named with its time, and one line per breach."""

from __future__ import annotations

import numpy as np

from mpcform.outputs.flight.check import FlightCheck
from mpcform.outputs.flight.safety import ClosestPair, closest_pair, separation_breaches


def test_closest_pair_names_the_pair_and_the_time() -> None:
    t = np.array([0.0, 0.5, 1.0])
    p = np.zeros((3, 3, 3))
    p[:, 1, 0] = [2.0, 0.4, 2.0]  # drone 1 comes to 0.4 m of drone 0 at t = 0.5 s
    p[:, 2, 1] = 5.0
    found = closest_pair(t, p)
    assert found == ClosestPair(0.4, 0.5, (0, 1))
    assert found.describe() == "drones 0 and 1 0.4 m apart at t = 0.50 s"
    assert closest_pair(t, p[:, :1]) is None


def test_one_line_per_breach() -> None:
    near, far = ClosestPair(0.3, 2.0, (1, 4)), ClosestPair(0.6, 1.0, (0, 2))
    assert separation_breaches(0.5, 0.01, far, far, far) == []
    assert separation_breaches(None, 0.01, near, near, near) == []
    planned = separation_breaches(0.5, 0.01, near, near, None)
    assert planned == [
        "the planned flight brings drones 1 and 4 0.3 m apart at t = 2.00 s (d_min = 0.5 m): do not fly it"
    ]
    retimed = separation_breaches(0.5, 0.01, far, ClosestPair(0.47, 3.0, (2, 3)), near)
    assert len(retimed) == 2 and "lower --tolerance" in retimed[0] and "quadrotor plant" in retimed[1]
    assert separation_breaches(0.5, 0.02, far, ClosestPair(0.47, 3.0, (2, 3)), None) == []  # within 2 tol


def test_a_flight_check_below_d_min_is_not_within_tolerance() -> None:
    ok = FlightCheck(0.01, 0, 1.0, 0.02, 0.01, ClosestPair(0.55, 2.0, (0, 1)), 0.5)
    assert ok.within_tolerance and ok.record()["closest_pair"] == [0, 1]
    close = FlightCheck(0.01, 0, 1.0, 0.02, 0.01, ClosestPair(0.455, 2.0, (0, 1)), 0.5)
    assert not close.within_tolerance and close.record()["within_tolerance"] is False
