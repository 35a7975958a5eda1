"""Fly an export on the quadrotor plant: the true tracking error and separation of the swarm.

Every drone starts at rest at the start of its pieces on a :class:`~mpcform.sim.quadrotor.
QuadrotorPlant` (drone-models' Crazyflie model flown by a PID cascade at 500 Hz). Every
``INTERVAL_S`` the pieces give each drone's position and velocity; the plant's position loop
follows ``p(t_k) + v(t_k) (t - t_k)`` at its inner rate (the cascade has no acceleration
feedforward). The report: the largest distance between the true and the exported positions, the
smallest true pairwise distance, and the declared tolerance they are held to: the plant's robust
margin (``QuadrotorPlantSpec().robustness``, one control interval of the run at the export's
acceleration limit) plus the fit tolerance. Without drone-models the check is skipped (None).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import metadata
from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.outputs.flight.polynomial import PiecewisePolynomial
from mpcform.outputs.flight.safety import ClosestPair, closest_pair
from mpcform.sim.plant_spec import QuadrotorPlantSpec

INTERVAL_S = 0.02  # 10 inner steps of the 500 Hz plant (the plant records >= 10 samples per call)


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
        return self.max_error_m <= self.declared_tolerance_m and apart

    def record(self) -> dict[str, Any]:
        return {
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
) -> FlightCheck | None:
    """Fly ``n`` drones' pieces (series drone * 4 + x, y, z, yaw) on the quadrotor plant; the
    closest true pair is checked against ``d_min_m``."""
    if not drone_models_available():
        return None
    spec = QuadrotorPlantSpec()
    margin = spec.robustness(3, control_dt_s, a_max_mps2).margin_m
    plant = spec.build(n, 3)
    steps = int(np.floor(poly.duration_s / INTERVAL_S + 1e-9))  # the last < 20 ms are at rest
    t_k = np.arange(steps + 1) * INTERVAL_S
    pos = poly.evaluate(t_k).reshape(-1, n, 4)[..., :3]
    vel = poly.evaluate(t_k, 1).reshape(-1, n, 4)[..., :3]
    plant.reset(pos[0])
    times: list[Array] = []
    true: list[Array] = []
    for k in range(steps):
        samples = plant.advance(vel[k], INTERVAL_S, pos[k])
        times.append(samples.t_s[1:])
        true.append(samples.p_true_m[1:])
    t = np.concatenate(times)
    p_true = np.concatenate(true)
    err = np.linalg.norm(p_true - poly.evaluate(t).reshape(-1, n, 4)[..., :3], axis=-1)
    j, i = np.unravel_index(int(np.argmax(err)), err.shape)
    closest = closest_pair(t, p_true)
    return FlightCheck(
        float(err[j, i]), int(i), float(t[j]), float(margin), fit_tolerance_m, closest, d_min_m
    )
