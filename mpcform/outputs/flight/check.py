"""Fly an export on the quadrotor plant (and, if asked, open loop in crazyflow): the true
tracking error and separation of the swarm.

Every drone starts at rest at the start of its pieces on a :class:`~mpcform.sim.quadrotor.
QuadrotorPlant` (drone-models' Crazyflie model flown by a PID cascade at 500 Hz). Every
``INTERVAL_S`` the pieces give each drone's position, velocity and acceleration, which the plant
follows as a full-state setpoint (:meth:`~mpcform.sim.quadrotor.QuadrotorPlant.follow`: the
acceleration fed forward, as the firmware's controllers take it from ``cmdFullState``; without it
the cascade lags a time-optimal flight by 0.14-0.16 m). The report: the largest distance between
the true and the exported positions, the smallest true pairwise distance, and the declared
tolerance they are held to: the plant's robust margin (``QuadrotorPlantSpec().robustness``, one
control interval of the run at the export's acceleration limit) plus the fit tolerance. Without
drone-models the check is skipped (None).

:func:`fly_export_crazyflow` flies the pieces' full state (position, velocity, acceleration, yaw
and body rates at 100 Hz, what ``cmdFullState`` takes) open loop through crazyflow's Mellinger
controller (:meth:`mpcform.sim.crazyflow.CrazyflowPlant.fly_full_state`), the drones hovering at
the start; its declared tolerance is a Crazyflie's tracking allowance plus the fit tolerance, and
its contacts, floor contacts and flips are reported.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from importlib import metadata
from typing import Any, cast

import numpy as np

from mpcform._validate import Array
from mpcform.control.setpoints import FullState
from mpcform.outputs.flight.limits import flat_state
from mpcform.outputs.flight.polynomial import PiecewisePolynomial
from mpcform.outputs.flight.safety import ClosestPair, ObstacleApproach, ObstacleCheck, closest_pair
from mpcform.sim.crazyflow import CrazyflowPlant
from mpcform.sim.plant_spec import QuadrotorPlantSpec
from mpcform.sim.quadrotor import QuadrotorPlant
from mpcform.world.limits import PLATFORM_TRACKING_M

INTERVAL_S = 0.02  # 10 inner steps of the 500 Hz plant (the plant records >= 10 samples per call)
CONTACT_EVENTS = ("drone_contacts", "floor_contacts", "flipped")


@dataclass(frozen=True)
class FlightCheck:
    """True tracking error [m] (worst drone, time), the declared tracking tolerance [m] = plant
    margin + fit tolerance, the closest true pair (None for one drone) and the run's d_min [m]."""

    max_error_m: float
    error_drone: int
    error_t_s: float
    plant_margin_m: float
    fit_tolerance_m: float
    closest: ClosestPair | None = None
    d_min_m: float | None = None
    events: dict[str, Any] | None = None  # crazyflow's contacts, floor contacts and flips
    obstacle: ObstacleApproach | None = None  # the deepest approach into an obstacle's clearance

    @property
    def min_separation_m(self) -> float:
        """The true minimum separation [m] (inf for one drone)."""
        return float("inf") if self.closest is None else self.closest.distance_m

    @property
    def declared_tolerance_m(self) -> float:
        return self.plant_margin_m + self.fit_tolerance_m

    @property
    def within_tolerance(self) -> bool:
        """Tracked within the declared tolerance and no pair closer than d_min."""
        apart = self.d_min_m is None or self.min_separation_m >= self.d_min_m
        calm = not self.events or not any(self.events.get(k) for k in CONTACT_EVENTS)
        clear = self.obstacle is None or self.obstacle.inside_m <= 0.0
        return self.max_error_m <= self.declared_tolerance_m and apart and calm and clear

    def describe(self) -> str:
        """What broke the tolerance: contacts, a pair closer than d_min, or the tracking error."""
        said = [f"{k.replace('_', ' ')}: {v}" for k, v in (self.events or {}).items() if v]
        if self.d_min_m is not None and self.closest is not None and self.min_separation_m < self.d_min_m:
            said.append(f"{self.closest.describe()}, closer than d_min = {self.d_min_m:g} m")
        if self.obstacle is not None and self.obstacle.inside_m > 0.0:
            said.append(self.obstacle.describe())
        if self.max_error_m > self.declared_tolerance_m:
            said.append(
                f"drone {self.error_drone} {self.max_error_m:.3g} m off at t = {self.error_t_s:.2f} s, "
                f"beyond {self.declared_tolerance_m:.3g} m"
            )
        return "; ".join(said) or "within tolerance"

    def record(self) -> dict[str, Any]:
        return (
            {
                "max_tracking_error_m": self.max_error_m,
                "drone": self.error_drone,
                "t_s": self.error_t_s,
                "min_separation_m": self.min_separation_m,
                "closest_pair": None if self.closest is None else list(self.closest.pair),
                "closest_t_s": None if self.closest is None else self.closest.t_s,
                "d_min_m": self.d_min_m,
                "plant_margin_m": self.plant_margin_m,
                "fit_tolerance_m": self.fit_tolerance_m,
                "declared_tolerance_m": self.declared_tolerance_m,
                "within_tolerance": self.within_tolerance,
            }
            | ({} if self.events is None else {"events": self.events})
            | ({} if self.obstacle is None else {"obstacle_inside_m": self.obstacle.inside_m})
        )


def drone_models_available() -> bool:
    try:
        metadata.distribution("drone-models")
    except metadata.PackageNotFoundError:
        return False
    return True


def fly_export(
    poly: PiecewisePolynomial,
    n: int,
    fit_tolerance_m: float,
    control_dt_s: float,
    a_max_mps2: float,
    d_min_m: float | None = None,
    metric: Array | None = None,
    obstacles: ObstacleCheck | None = None,
) -> FlightCheck | None:
    """Fly ``n`` drones' pieces (series drone * 4 + x, y, z, yaw) on the quadrotor plant; the
    closest true pair (in the downwash ``metric`` when given) is checked against ``d_min_m``, the
    true path against the ``obstacles``."""
    if not drone_models_available():
        return None
    spec = QuadrotorPlantSpec()
    margin = spec.robustness(3, control_dt_s, a_max_mps2).margin_m
    plant = cast(QuadrotorPlant, spec.build(n, 3))
    steps = int(np.floor(poly.duration_s / INTERVAL_S + 1e-9))  # the last < 20 ms are at rest
    t_k = np.arange(steps + 1) * INTERVAL_S
    pos = poly.evaluate(t_k).reshape(-1, n, 4)[..., :3]
    vel = poly.evaluate(t_k, 1).reshape(-1, n, 4)[..., :3]
    acc = poly.evaluate(t_k, 2).reshape(-1, n, 4)[..., :3]
    plant.reset(pos[0])
    times: list[Array] = []
    true: list[Array] = []
    for k in range(steps):  # the pieces' full state, as cmdFullState gives it to a Crazyflie
        samples = plant.follow(pos[k], vel[k], acc[k], INTERVAL_S)
        times.append(samples.t_s[1:])
        true.append(samples.p_true_m[1:])
    t = np.concatenate(times)
    p_true = np.concatenate(true)
    return _flight_check(poly, n, t, p_true, float(margin), fit_tolerance_m, d_min_m, metric, None, obstacles)


def fly_export_crazyflow(
    poly: PiecewisePolynomial,
    n: int,
    fit_tolerance_m: float,
    d_min_m: float | None = None,
    metric: Array | None = None,
    obstacles: ObstacleCheck | None = None,
) -> FlightCheck | None:
    """Fly ``n`` drones' pieces open loop in crazyflow (module docstring); None without it."""
    if importlib.util.find_spec("crazyflow") is None:
        return None
    plant = CrazyflowPlant(n, 3)
    t = np.arange(0.0, poly.duration_s, 1.0 / plant.control_hz)
    st = flat_state(poly, t, n)
    setpoints = FullState(t, st["pos"], st["vel"], st["acc"], st["yaw"], st["omega"])
    t_true, p_true = plant.fly_full_state(st["pos"][0], setpoints)
    events = {k: v for k, v in plant.events.items() if k in CONTACT_EVENTS}
    return _flight_check(
        poly, n, t_true, p_true, PLATFORM_TRACKING_M, fit_tolerance_m, d_min_m, metric, events, obstacles
    )


def _flight_check(
    poly: PiecewisePolynomial,
    n: int,
    t_s: Array,
    p_true_m: Array,
    margin_m: float,
    fit_tolerance_m: float,
    d_min_m: float | None,
    metric: Array | None,
    events: dict[str, Any] | None = None,
    obstacles: ObstacleCheck | None = None,
) -> FlightCheck:
    """The check of true positions ``p_true_m`` (K, n, 3) at ``t_s`` (K,) against the pieces: the
    worst tracking error, the closest true pair and the deepest approach to an obstacle."""
    err = np.linalg.norm(p_true_m - poly.evaluate(t_s).reshape(-1, n, 4)[..., :3], axis=-1)
    j, i = np.unravel_index(int(np.argmax(err)), err.shape)
    closest = closest_pair(t_s, p_true_m, metric)
    approach = None if obstacles is None else obstacles.approach(t_s, p_true_m)
    return FlightCheck(
        float(err[j, i]), int(i), float(t_s[j]), margin_m, fit_tolerance_m, closest, d_min_m, events, approach
    )
