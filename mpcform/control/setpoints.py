"""Full-state setpoints of one control interval: what a Crazyflie's ``cmdFullState`` takes.

The planner's command ``u`` holds over ``[t_k, t_k + dt]`` and its plan takes a drone along
``p(t) = p_k + (t - t_k) u`` from the *measured* start ``p_k`` (the single integrator of eq. 14's
plan, restarted at every measurement, so the setpoint path cannot drift from where the drone is).
Sampled at the setpoint rate, each drone gets position ``p(t_j)``, velocity ``u``, acceleration 0
(the plan's velocity is constant within the interval), yaw 0 and body rates 0; a planar plan flies
at ``altitude_m``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError


@dataclass(frozen=True, eq=False)
class FullState:
    """Setpoints at times ``t_s`` (k,) for n drones: ``pos_m``, ``vel_mps``, ``acc_mps2`` (k, n, 3),
    ``yaw_rad`` (k, n) and ``omega_rad_s`` (k, n, 3), in the world frame (z up)."""

    t_s: Array
    pos_m: Array
    vel_mps: Array
    acc_mps2: Array
    yaw_rad: Array
    omega_rad_s: Array

    def state_control(self) -> Array:
        """The rows (k, n, 16) of crazyflow's state control: position, velocity, acceleration,
        attitude quaternion (x, y, z, w; only its yaw is used) and body rates."""
        k, n = self.yaw_rad.shape
        out = np.zeros((k, n, 16))
        out[..., 0:3], out[..., 3:6], out[..., 6:9] = self.pos_m, self.vel_mps, self.acc_mps2
        out[..., 11], out[..., 12] = np.sin(self.yaw_rad / 2.0), np.cos(self.yaw_rad / 2.0)
        out[..., 13:16] = self.omega_rad_s
        return out


def ticks_per_interval(dt_s: float, rate_hz: float, field: str = "setpoint_rate") -> int:
    """Setpoints per interval: ``dt rate``, which must be a whole number >= 1."""
    ratio = positive("simulation.dt", dt_s) * positive(field, rate_hz)
    ticks = int(round(ratio))
    if ticks < 1 or abs(ratio - ticks) > 1e-9 * ratio:
        raise ValidationError(
            field, f"expected a multiple of the control rate 1/dt = {1 / dt_s:g} Hz, got {rate_hz:g}"
        )
    return ticks


def interval_setpoints(
    start_m: Array, command_mps: Array, t_s: float, dt_s: float, rate_hz: float, altitude_m: float = 1.0
) -> FullState:
    """The setpoints (module docstring) of the interval from ``t_s`` [s] for drones measured at
    ``start_m`` (n, d) flying ``command_mps`` (n, d), at ``rate_hz``: ``dt rate`` samples, the first
    at ``t_s``."""
    n, dim = start_m.shape
    k = ticks_per_interval(dt_s, rate_hz)
    tau = np.arange(k) / rate_hz
    pos, vel = np.zeros((k, n, 3)), np.zeros((k, n, 3))
    pos[:, :, :dim] = start_m + tau[:, None, None] * command_mps
    vel[:, :, :dim] = command_mps
    if dim == 2:
        pos[:, :, 2] = altitude_m
    zeros = np.zeros((k, n, 3))
    return FullState(t_s + tau, pos, vel, zeros, np.zeros((k, n)), zeros.copy())
