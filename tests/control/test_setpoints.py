"""Full-state setpoints of an interval: the plan's path from the measured start, in cmdFullState's terms."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.control.setpoints import interval_setpoints, ticks_per_interval
from mpcform.errors import ValidationError


def test_setpoints_follow_the_plan_from_the_measured_start() -> None:
    rng = np.random.default_rng(0)
    start, u = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    sp = interval_setpoints(start, u, 2.0, 0.1, 100.0)
    assert sp.t_s.shape == (10,) and sp.t_s[0] == 2.0
    np.testing.assert_allclose(sp.t_s - 2.0, np.arange(10) / 100.0, atol=1e-15)
    np.testing.assert_array_equal(sp.pos_m[0], start)
    np.testing.assert_allclose(sp.pos_m, start + (sp.t_s - 2.0)[:, None, None] * u, atol=1e-15)
    np.testing.assert_array_equal(sp.vel_mps, np.broadcast_to(u, (10, 5, 3)))
    assert not sp.acc_mps2.any() and not sp.yaw_rad.any() and not sp.omega_rad_s.any()


def test_planar_setpoints_hold_the_altitude() -> None:
    sp = interval_setpoints(np.zeros((2, 2)), np.ones((2, 2)), 0.0, 0.05, 100.0, altitude_m=1.5)
    assert sp.pos_m.shape == (5, 2, 3)
    assert np.all(sp.pos_m[..., 2] == 1.5) and np.all(sp.vel_mps[..., 2] == 0.0)


def test_state_control_rows() -> None:
    sp = interval_setpoints(np.zeros((1, 3)), np.array([[1.0, 2.0, 3.0]]), 0.0, 0.1, 20.0)
    rows = sp.state_control()
    assert rows.shape == (2, 1, 16)
    np.testing.assert_allclose(rows[1, 0, :6], [0.05, 0.1, 0.15, 1.0, 2.0, 3.0], atol=1e-15)
    np.testing.assert_array_equal(rows[1, 0, 9:13], [0.0, 0.0, 0.0, 1.0])  # yaw 0: (x, y, z, w)


@pytest.mark.parametrize("rate", [15.0, 5.0, -1.0])
def test_rates_that_are_no_multiple_of_the_control_rate_are_refused(rate: float) -> None:
    with pytest.raises(ValidationError, match="setpoint_rate"):
        ticks_per_interval(0.1, rate)
