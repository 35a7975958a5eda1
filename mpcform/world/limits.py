"""The limits a user asks for (a scenario's ``[limits]``, or :class:`Limits` in Python), shared by
the controllers, the MPC planner and the metrics; what a planner derives from them for a plant
that may be off its plan is :mod:`mpcform.world.bounds`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, positive
from mpcform.errors import ValidationError, shown

PLATFORM_TILT_RAD = float(np.radians(20.0))
"""Tilt of the airframe a plan is flown on when nothing says otherwise (a Crazyflie 2.x)."""
DEFAULT_A_MAX_MPS2 = float(0.5 * 9.81 * np.tan(PLATFORM_TILT_RAD))
"""The MPC's command-change bound [m/s^2] when ``a_max`` is unset (1.79): half the horizontal
acceleration of a 20 deg tilt, so that the position loop keeps the other half for its own
corrections; the linear plants' default too (:func:`mpcform.sim.margin.default_a_max`). A step
beyond what the firmware's attitude loop can follow from hover flips a Crazyflie."""
CRAZYSWARM_ELLIPSOID_M = (0.12, 0.12, 0.3)
"""Crazyswarm's collision ellipsoid of one Crazyflie (radii x, y, z [m]): a pair needs 0.24 m
horizontally and 0.6 m vertically, the downwash below a rotor reaching further than its arms."""


def crazyswarm_downwash(d_min_m: float) -> float:
    """``kappa`` of ``limits.downwash = "crazyswarm"``: pairs ``d_min`` apart horizontally keep
    Crazyswarm's vertical 0.6 m (``kappa = 0.6 / d_min``, at least 1), for ``d_min >= 0.24 m``."""
    horizontal, vertical = 2.0 * CRAZYSWARM_ELLIPSOID_M[0], 2.0 * CRAZYSWARM_ELLIPSOID_M[2]
    if d_min_m < horizontal:
        raise ValidationError(
            "limits.downwash",
            f"'crazyswarm' keeps d_min = {d_min_m:g} m horizontally, below the ellipsoid's "
            f"{horizontal:g} m: expected d_min >= {horizontal:g} m",
        )
    return max(1.0, vertical / d_min_m)


PLATFORM_CLIMB_MPS = 0.7
"""A Crazyflie 2.x's (cf2x_L250) vertical speed bound [m/s] for velocity commands flown online
(the crazyflow plant's default ``limits.v_max_z``): the Mellinger controller turns a vertical
velocity error into thrust at 17 m/s^2 per m/s, and climbs of 0.9 m/s while turning saturated the
motors (the attitude loop then loses its torque and the drone flips: 1 of 4 online flights of
swap_spatial_20 under CPU load in crazyflow); at 0.7 m/s none of 16 did."""
PLATFORM_TRACKING_M = 0.05
"""A Crazyflie 2.x's (cf2x_L250) tracking allowance per drone [m] (``--flyable``): the largest
absolute per-drone error of the firmware's Mellinger position loop flying exported setpoints,
3.5-5 cm measured in crazyflow (utiasDSL's simulator) on the bundled swaps, rounded up."""


@dataclass(frozen=True, eq=False)
class Limits:
    """Speed, separation, acceleration and geofence limits (None = unset).

    ``v_max_mps``: speed bound per drone [m/s]; ``d_min_m``: minimum distance between two drones
    [m]; ``a_max_mps2``: componentwise bound on command changes, ``|u_j - u_{j-1}| <= a_max dt``
    [m/s^2] (inf: no bound; the MPC takes :data:`DEFAULT_A_MAX_MPS2` for None, see
    :func:`mpcform.world.bounds.planning_bounds`); ``geofence_min_m`` / ``geofence_max_m``:
    axis-aligned box (d,) the drones stay in (a floor is ``geofence_min_m[2]``; use +-inf for open sides);
    ``downwash_kappa``: separation is measured as ``||diag(1, 1, 1/kappa) (p_i - p_k)||``
    (spatial only, kappa >= 1);
    ``tracking_m``: room per drone for the position controller's tracking error when the plan is
    flown as setpoints (:data:`PLATFORM_TRACKING_M` for a Crazyflie; 0: none, and ``export``
    refuses the run), applied by :func:`mpcform.world.bounds.planning_bounds`; ``v_max_z_mps``:
    vertical speed bound [m/s]
    (spatial, with ``v_max``): the velocity set is squeezed along z into the spheroid of semi-axes
    ``v_max, v_max, v_max_z`` (:meth:`speed_scale`).
    """

    v_max_mps: float | None = None
    d_min_m: float | None = None
    a_max_mps2: float | None = None
    geofence_min_m: Array | None = None
    geofence_max_m: Array | None = None
    downwash_kappa: float | None = None
    tracking_m: float = 0.0
    v_max_z_mps: float | None = None

    def __post_init__(self) -> None:
        for name in ("v_max_mps", "d_min_m", "a_max_mps2", "downwash_kappa", "tracking_m", "v_max_z_mps"):
            _number(f"limits.{_key(name)}", getattr(self, name))
        if self.v_max_z_mps is not None:
            object.__setattr__(self, "v_max_z_mps", positive("limits.v_max_z", self.v_max_z_mps))
        object.__setattr__(self, "tracking_m", positive("limits.tracking", self.tracking_m, allow_zero=True))
        for name in ("v_max_mps", "d_min_m", "a_max_mps2", "downwash_kappa"):
            value = getattr(self, name)
            if name == "a_max_mps2" and _is_inf(value):
                object.__setattr__(self, name, float("inf"))
            elif value is not None:
                object.__setattr__(self, name, positive(f"limits.{_key(name)}", value))
        if self.downwash_kappa is not None and self.downwash_kappa < 1.0:
            raise ValidationError("limits.downwash", f"expected kappa >= 1, got {self.downwash_kappa}")
        lo, hi = self.geofence_min_m, self.geofence_max_m
        if (lo is None) != (hi is None):
            raise ValidationError(
                "limits.geofence_min", "give both geofence_min and geofence_max, or neither"
            )
        if lo is not None and hi is not None:
            lo_a = _bound("limits.geofence_min", lo)
            hi_a = _bound("limits.geofence_max", hi)
            if lo_a.shape != hi_a.shape or np.any(lo_a >= hi_a):
                raise ValidationError(
                    "limits.geofence_max",
                    f"expected geofence_min < geofence_max per axis, got {lo_a} and {hi_a}",
                )
            object.__setattr__(self, "geofence_min_m", lo_a)
            object.__setattr__(self, "geofence_max_m", hi_a)

    def speed_scale(self, dim: int) -> Array:
        """Per-axis factors (d,) that map the velocity set's spheroid onto the ball of radius
        ``v_max``: 1, and ``v_max / v_max_z`` on z when that squeezes it (``|u_z| <= v_max_z``)."""
        scale = np.ones(dim)
        v, vz = self.v_max_mps, self.v_max_z_mps
        if dim == 3 and v is not None and vz is not None and vz < v:
            scale[2] = v / vz
        return scale

    @property
    def a_max_bounded(self) -> bool:
        """Whether ``a_max`` is a finite bound (unset and inf are not)."""
        return self.a_max_mps2 is not None and np.isfinite(self.a_max_mps2)


def _is_inf(value: object) -> bool:
    try:
        return float(value) == float("inf")  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


def _number(field: str, value: object) -> None:
    """``value`` is None or a real number (not a string, a bool or a complex): no silent coercion."""
    if value is None or isinstance(value, np.floating | np.integer):
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValidationError(field, f"expected a number, got {shown(value)}")


def _key(attr: str) -> str:
    return attr.rsplit("_", 1)[0].replace("_kappa", "") if attr != "downwash_kappa" else "downwash"


def _bound(field: str, value: object) -> Array:
    arr = np.array(value, dtype=float)
    if arr.ndim != 1 or arr.shape[0] not in (2, 3) or np.any(np.isnan(arr)):
        raise ValidationError(field, f"expected 2 or 3 numbers (inf allowed), got {shown(value)}")
    return arr
