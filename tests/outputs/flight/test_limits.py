"""Flatness body rates (against Crazyswarm2's formula), peaks and limit messages."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.outputs.flight.limits import (
    DEFAULT_MAX_ACC_MPS2,
    FlightLimits,
    body_rates,
    envelope,
    platform_thrust_acc_mps2,
)


def _crazyswarm_omega(acc, jerk, yaw, dyaw):  # uav_trajectory.py, Polynomial4D.eval
    thrust = acc + np.array([0, 0, 9.81])
    z_body = thrust / np.linalg.norm(thrust)
    x_world = np.array([np.cos(yaw), np.sin(yaw), 0])
    y_body = np.cross(z_body, x_world)
    y_body /= np.linalg.norm(y_body)
    x_body = np.cross(y_body, z_body)
    h_w = (jerk - np.dot(jerk, z_body) * z_body) / np.linalg.norm(thrust)
    return np.array([-np.dot(h_w, y_body), np.dot(h_w, x_body), z_body[2] * dyaw])


def test_body_rates_match_crazyswarm() -> None:
    rng = np.random.default_rng(3)
    acc, jerk = rng.normal(0, 2, (50, 3)), rng.normal(0, 10, (50, 3))
    yaw, dyaw = rng.uniform(-3, 3, 50), rng.normal(0, 1, 50)
    ours = body_rates(acc, jerk, yaw, dyaw)
    for k in range(50):
        assert np.allclose(ours[k], _crazyswarm_omega(acc[k], jerk[k], yaw[k], dyaw[k]))


def test_hover_with_sideways_jerk_tilts_at_jerk_over_g() -> None:
    omega = body_rates(np.zeros((1, 3)), np.array([[9.81, 0.0, 0.0]]), np.zeros(1), np.zeros(1))
    assert np.allclose(omega, [[0.0, 1.0, 0.0]])  # pitching at 1 rad/s


def test_envelope_names_drone_time_value() -> None:
    t = np.array([0.0, 1.0])
    vel = np.zeros((2, 2, 3))
    vel[1, 1, 0] = 2.0
    z = np.zeros((2, 2, 3))
    env = envelope(t, vel, z, z, z)
    assert (env.speed.drone, env.speed.t_s, env.speed.value) == (1, 1.0, 2.0)
    (line,) = env.violations(FlightLimits(max_speed_mps=1.5))
    assert line == "drone 1 at t = 1.000 s: speed 2 m/s exceeds 1.5 m/s (--max-speed)"
    assert env.violations(FlightLimits()) == [
        "drone 1 at t = 1.000 s: speed 2 m/s exceeds 1 m/s (--max-speed)"
    ]


def test_defaults_and_validation() -> None:
    assert DEFAULT_MAX_ACC_MPS2 == pytest.approx(0.5 * 9.81 * np.tan(np.radians(20.0)))  # the planner's
    with pytest.raises(ValidationError, match="max_speed"):
        FlightLimits(max_speed_mps=0.0)
    with pytest.raises(ValidationError, match="max_thrust"):
        FlightLimits(max_thrust_acc_mps2=5.0)
    thrust = platform_thrust_acc_mps2()
    assert thrust is None or 9.81 < thrust < 40.0
