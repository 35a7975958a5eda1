"""What a Crazyflie 2.x can fly: speed, acceleration, jerk, body rate and thrust of a polynomial.

Differential flatness (the quadrotor's state follows from position, its derivatives and yaw):
the thrust direction is ``z_b = (a + g e_z) / |a + g e_z|``; with the yaw heading
``x_c = (cos yaw, sin yaw, 0)``, ``y_b = z_b x x_c / |.|`` and ``x_b = y_b x z_b``; the jerk
normal to the thrust, ``h = (j - (j . z_b) z_b) / |a + g e_z|``, gives the body rates
``omega = (-h . y_b, h . x_b, yaw' z_b . e_z)`` [rad/s] (the formula of Crazyswarm's
``uav_trajectory.py`` and of the firmware's full-state setpoint).

Defaults and their sources (override with the export's ``--max-*`` options):

- speed 1.0 m/s: crazyflie-firmware ``platform_defaults_cf2.h``, ``PID_POS_VEL_X/Y/Z_MAX``, the
  velocity the position PID may ask for;
- acceleration 1.79 m/s^2, half of g tan(20 deg) = 3.57 m/s^2 (the same file's
  ``PID_VEL_ROLL_MAX`` / ``PID_VEL_PITCH_MAX`` = 20 deg, the tilt the velocity PID may ask for):
  the planner's platform bound, which leaves the position loop the other half for its
  corrections (:data:`DEFAULT_MAX_ACC_MPS2`);
- thrust: the collective force ``m |a + g e_z|`` must stay below the largest force of
  drone-models' ``cf2x_L250`` parameters (``acc_coef + cmd_f_coef * 4 thrust_max``, mass
  ``mass``, read by :func:`mpcform.sim.so_rpy.load_params`); skipped without drone-models;
- body rate 10 rad/s and jerk 30 m/s^3: no firmware limit exists for either in the PID cascade;
  these are this project's conservative choices (a jerk of 30 m/s^3 at hover is about 3 rad/s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs.flight.polynomial import PiecewisePolynomial
from mpcform.world.limits import DEFAULT_A_MAX_MPS2

GRAVITY_MPS2 = 9.81
DEFAULT_MAX_SPEED_MPS = 1.0
DEFAULT_MAX_ACC_MPS2 = DEFAULT_A_MAX_MPS2
"""The planner's platform bound (1.79 m/s^2, half a 20 deg tilt): a time-optimal flight at the
whole tilt's 3.57 m/s^2 flipped a drone in crazyflow and left the Mellinger loop 5 m off."""
DEFAULT_MAX_JERK_MPS3 = 30.0
DEFAULT_MAX_BODY_RATE_RAD_S = 10.0
DEFAULT_PLATFORM = "cf2x_L250"


@dataclass(frozen=True)
class FlightLimits:
    """Largest speed [m/s], acceleration [m/s^2], jerk [m/s^3], body rate [rad/s] and
    thrust-to-mass ratio ``|a + g|`` [m/s^2] (None: not checked) of an export."""

    max_speed_mps: float = DEFAULT_MAX_SPEED_MPS
    max_acc_mps2: float = DEFAULT_MAX_ACC_MPS2
    max_jerk_mps3: float = DEFAULT_MAX_JERK_MPS3
    max_body_rate_rad_s: float = DEFAULT_MAX_BODY_RATE_RAD_S
    max_thrust_acc_mps2: float | None = None

    def __post_init__(self) -> None:
        for name in ("max_speed_mps", "max_acc_mps2", "max_jerk_mps3", "max_body_rate_rad_s"):
            positive(
                name.removesuffix("_mps").removesuffix("_mps2").removesuffix("_mps3").removesuffix("_rad_s"),
                getattr(self, name),
            )
        if self.max_thrust_acc_mps2 is not None and not self.max_thrust_acc_mps2 > GRAVITY_MPS2:
            raise ValidationError("max_thrust", f"expected more than g, got {self.max_thrust_acc_mps2!r}")


def platform_thrust_acc_mps2(platform: str = DEFAULT_PLATFORM) -> float | None:
    """Largest collective force per mass [m/s^2] of a drone-models platform (None without it)."""
    from mpcform.sim.so_rpy import load_params

    try:
        p = load_params(platform)
    except MPCFormError:
        return None
    return (p.acc_coef_N + p.cmd_f_coef * p.thrust_max_N) / p.mass_kg


def body_rates(acc: Array, jerk: Array, yaw: Array, yaw_rate: Array) -> Array:
    """Body rates omega (..., 3) [rad/s] from acceleration, jerk (..., 3), yaw and its rate (...)."""
    thrust = acc + np.array([0.0, 0.0, GRAVITY_MPS2])
    norm = np.linalg.norm(thrust, axis=-1, keepdims=True)
    z_b = thrust / norm
    x_c = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
    y_b = np.cross(z_b, x_c)
    y_b /= np.linalg.norm(y_b, axis=-1, keepdims=True)
    x_b = np.cross(y_b, z_b)
    h = (jerk - np.sum(jerk * z_b, axis=-1, keepdims=True) * z_b) / norm
    return np.stack([-np.sum(h * y_b, axis=-1), np.sum(h * x_b, axis=-1), z_b[..., 2] * yaw_rate], axis=-1)


@dataclass(frozen=True)
class Peak:
    """The largest value of one quantity over the swarm: drone, time [s] and value."""

    drone: int
    t_s: float
    value: float


@dataclass(frozen=True)
class FlightEnvelope:
    """Peaks of speed, acceleration, jerk, body rate and thrust per mass of an export."""

    speed: Peak
    acc: Peak
    jerk: Peak
    body_rate: Peak
    thrust_acc: Peak

    def violations(self, limits: FlightLimits) -> list[str]:
        """One line per exceeded limit, naming the drone, the time and the value."""
        checks = [
            ("speed", self.speed, limits.max_speed_mps, "m/s", "--max-speed"),
            ("acceleration", self.acc, limits.max_acc_mps2, "m/s^2", "--max-acc"),
            ("jerk", self.jerk, limits.max_jerk_mps3, "m/s^3", "--max-jerk"),
            ("body rate", self.body_rate, limits.max_body_rate_rad_s, "rad/s", "--max-body-rate"),
            ("thrust per mass", self.thrust_acc, limits.max_thrust_acc_mps2, "m/s^2", "the platform"),
        ]
        return [
            f"drone {peak.drone} at t = {peak.t_s:.3f} s: {name} {peak.value:.4g} {unit} exceeds "
            f"{limit:.4g} {unit} ({flag})"
            for name, peak, limit, unit, flag in checks
            if limit is not None and peak.value > limit
        ]


def envelope(t_s: Array, vel: Array, acc: Array, jerk: Array, omega: Array) -> FlightEnvelope:
    """Peaks of (T, n, 3) samples at ``t_s`` (T,)."""
    thrust = acc + np.array([0.0, 0.0, GRAVITY_MPS2])

    def peak(x: Array) -> Peak:
        norm = np.linalg.norm(x, axis=-1)
        j, i = np.unravel_index(int(np.argmax(norm)), norm.shape)
        return Peak(int(i), float(t_s[j]), float(norm[j, i]))

    return FlightEnvelope(peak(vel), peak(acc), peak(jerk), peak(omega), peak(thrust))


def flat_state(poly: PiecewisePolynomial, t_s: Array, n: int) -> dict[str, Array]:
    """Position, velocity, acceleration, jerk (T, n, 3), yaw, yaw rate (T, n) and body rates
    omega (T, n, 3) of ``n`` drones' pieces (series drone * 4 + x, y, z, yaw) at ``t_s``."""
    d = [poly.evaluate(t_s, r).reshape(t_s.shape[0], n, 4) for r in range(4)]
    state = {
        "pos": d[0][..., :3],
        "vel": d[1][..., :3],
        "acc": d[2][..., :3],
        "jerk": d[3][..., :3],
        "yaw": d[0][..., 3],
        "yaw_rate": d[1][..., 3],
    }
    state["omega"] = body_rates(state["acc"], state["jerk"], state["yaw"], state["yaw_rate"])
    return state
