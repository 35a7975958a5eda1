"""The whole flight, ground to ground: takeoff, a planned ascent, the mission, a planned descent,
landing.

Every drone takes off straight up from its place on the ground to ``hover_m`` (Crazyswarm2's
``takeoff``: the firmware's 7th-order rest-to-rest polynomial, :func:`vertical_leg_s` long so that
it keeps the speed, acceleration and jerk limits), flies the ascent, the mission and the descent
as one exported trajectory, and lands straight down. The ascent and the descent are planned by
the mission's own planner (:class:`mpcform.mpc.planner.MPCPlanner`, decoupled, on the exact single
integrator): from the takeoff layout at ``hover_m`` to the mission's first positions, and from its
last positions to the landing layout, keeping the run's ``d_min`` and tracking allowance and
:data:`FLOOR_CLEARANCE_M` above the floor (a geofence, lower if the mission starts or ends lower:
separation may push a drone down). The
vertical legs keep them because each layout's drones are that far apart horizontally.

A layout is the projection on the floor of the mission's first (takeoff) or last (landing)
positions when its drones are far enough apart there (:data:`LAYOUT_SPACING` times the distance
the planner keeps, so that it can reach them), else a square grid of that spacing
centred below them, each drone given the grid point that makes the total squared distance least
(``scipy.optimize.linear_sum_assignment``): drones stacked in z in a 3-D start do not take off
from one spot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.geometry import min_pair_distances
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.outputs.flight.limits import FlightLimits, flat_state
from mpcform.outputs.flight.pieces import CHECK_RATE_HZ, PhasePieces
from mpcform.reference.base import ConstantReference
from mpcform.sim.simulation import simulate
from mpcform.world.limits import Limits

HOVER_M = 0.3  # takeoff and landing height above the floor [m]
FLOOR_CLEARANCE_M = 0.15  # the ascent and the descent keep this far above the floor (a geofence)
ARRIVED_M = 0.002  # a phase ends once every drone is this close to its goal (then the goal itself)
BLEND_S = 1.0
"""The last gap to the goals (up to :data:`ARRIVED_M`) is closed over this long before a phase's
end, smoothly, not in its last interval: an export within a tolerance below that gap would
otherwise follow the jump and crawl to its end."""
PHASE_GAIN_PER_S = 2.0  # eq. 14's k in the ascent and descent
LAYOUT_SPACING = 1.25  # a grid layout's spacing per distance the planner keeps (so it can reach it)
LEG_MIN_S = 1.5  # the shortest takeoff or landing [s]
SLOW_SHARE = 0.05  # a retimed phase's slow end: every drone below this share of the speed limit
_SEPTIC = np.polynomial.Polynomial([0, 0, 0, 0, 35, -84, 70, -20])  # rest to rest, zero jerk at both ends
_S = np.linspace(0.0, 1.0, 2001)
LEG_PEAKS = tuple(float(np.abs(_SEPTIC.deriv(r)(_S)).max()) for r in (1, 2, 3))
"""Peak speed, acceleration and jerk of the septic leg over a height h in a time T, per ``h / T^r``
(2.19, 7.51 and 52.5)."""


@dataclass(frozen=True, eq=False)
class Flight:
    """The planned path (T, n, 3) [m] at the mission's ``dt_s``: the ascent, the mission and the
    descent, each a ``phases`` entry (name, its samples; an ascent or descent without motion is
    left out); the layouts (n, 2) [m] on the floor at ``floor_m``, the hover height [m], the
    vertical legs' durations [s] and, on given pads, the pad each drone takes off from (n,)."""

    positions_m: Array
    dt_s: float
    phases: tuple[tuple[str, slice], ...]
    takeoff_xy_m: Array
    landing_xy_m: Array
    floor_m: float
    hover_m: float
    takeoff_s: float
    land_s: float
    takeoff_pads: Array | None = None


def ground_layout(xy_m: Array, spacing_m: float) -> Array:
    """Positions (n, 2) on the floor: ``xy_m`` when its drones are ``spacing_m`` apart, else the
    nearest assignment to a square grid of that spacing centred below them (module docstring)."""
    n = xy_m.shape[0]
    if n < 2 or min_pair_distances(xy_m[None])[0] >= spacing_m:
        return xy_m.copy()
    side = math.ceil(math.sqrt(n))
    grid = spacing_m * np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)
    grid += xy_m.mean(axis=0) - grid.mean(axis=0)
    rows, cols = linear_sum_assignment(((xy_m[:, None] - grid[None]) ** 2).sum(-1))
    return grid[cols[np.argsort(rows)]]


def pad_layout(xy_m: Array, pads_m: Array, spacing_m: float) -> Array:
    """The pads (n,) of ``pads_m`` (k, 2), k >= n, the drones at ``xy_m`` go to: the assignment of
    least total squared distance (scipy's ``linear_sum_assignment``); pads closer than
    ``spacing_m`` are refused, naming the pair (the planner could not start from them)."""
    n, k = xy_m.shape[0], pads_m.shape[0]
    if k < n:
        raise ValidationError(
            "ground", f"{k} pad{'s' * (k != 1)} on the floor for {n} drones: expected at least {n}"
        )
    rows, cols = linear_sum_assignment(((xy_m[:, None] - pads_m[None]) ** 2).sum(-1))
    chosen = cols[np.argsort(rows)]
    gap = np.linalg.norm(pads_m[chosen][:, None] - pads_m[chosen][None], axis=-1) + np.diag(
        np.full(n, np.inf)
    )
    i, j = np.unravel_index(int(np.argmin(gap)), gap.shape)
    if n > 1 and gap[i, j] < spacing_m:
        a, b = sorted((int(chosen[i]), int(chosen[j])))
        raise ValidationError(
            "ground",
            f"pads {a} and {b} are {gap[i, j]:.3g} m apart, closer than the {spacing_m:.3g} m the "
            "planner keeps (d_min + 2 tracking): move them apart",
        )
    return chosen


def vertical_leg_s(height_m: float, limits: FlightLimits, slack: float = 0.9) -> float:
    """The shortest septic takeoff or landing over ``height_m`` within ``slack`` of the speed,
    acceleration and jerk limits (at least :data:`LEG_MIN_S`)."""
    v, a, j = LEG_PEAKS
    h = abs(height_m)
    lim = (limits.max_speed_mps, limits.max_acc_mps2, limits.max_jerk_mps3)
    need = (
        v * h / (slack * lim[0]),
        math.sqrt(a * h / (slack * lim[1])),
        (j * h / (slack * lim[2])) ** (1 / 3),
    )
    return max(LEG_MIN_S, *need)


def plan_phase(start_m: Array, goal_m: Array, dt_s: float, limits: Limits, name: str) -> Array:
    """The planner's path (T, n, 3) from ``start_m`` to ``goal_m`` (n, 3), until every drone is
    within :data:`ARRIVED_M` of its goal, the last sample the goal itself (the gap closed over
    :data:`BLEND_S`)."""
    travel = float(np.linalg.norm(goal_m - start_m, axis=-1).max())
    if travel <= ARRIVED_M:  # no motion: the goal alone
        return goal_m[None].copy()
    tpl, centre = Template.centred(goal_m)
    reference = ConstantReference(tpl, FormationState.from_param(centre))
    settings = MPCSettings(coupling="decoupled", gain_per_s=PHASE_GAIN_PER_S)
    planner = MPCPlanner(reference, dt_s, limits, settings)
    speed = limits.v_max_mps / math.sqrt(3.0) if limits.v_max_mps else 1.0  # the box's slowest
    duration = 3.0 * travel / speed + 20.0
    path = simulate(planner, start_m, duration).positions_m
    away = np.linalg.norm(path - goal_m, axis=-1).max(axis=1)
    late = np.flatnonzero(away > ARRIVED_M)
    if late.size and late[-1] == path.shape[0] - 1:
        far = np.flatnonzero(np.linalg.norm(path[-1] - goal_m, axis=-1) > ARRIVED_M)
        raise ValidationError(
            "flight",
            f"the planned {name} left drone{'s' * (far.size > 1)} {', '.join(map(str, far[:8]))} more than "
            f"{ARRIVED_M:g} m from {'its' if far.size == 1 else 'their'} goal after {duration:.3g} s",
        )
    end = 0 if not late.size else late[-1] + 1
    out = path[: end + 1].copy()
    blend = min(end, math.ceil(BLEND_S / dt_s))  # samples (end >= 1: the start is not arrived)
    x = np.arange(1, blend + 1) / blend
    smooth = x**3 * (10.0 - 15.0 * x + 6.0 * x**2)  # 0 to 1, its slope and curvature 0 at both
    out[end + 1 - blend :] += smooth[:, None, None] * (goal_m - out[-1])
    out[-1] = goal_m  # exactly, as the next phase starts
    return out


def whole_flight(
    mission_m: Array,
    dt_s: float,
    limits: Limits,
    flight_limits: FlightLimits,
    floor_m: float = 0.0,
    pads_m: Array | None = None,
) -> Flight:
    """The flight from the ground to ``mission_m`` (T, n, 3) [m] and back (module docstring):
    ``limits`` the run's (v_max, d_min, tracking allowance); ``pads_m`` (k, 2): the places on the
    floor to take off from and land on (None: :func:`ground_layout`'s)."""
    first, last = mission_m[0], mission_m[-1]
    hover = floor_m + HOVER_M
    bottom = min(floor_m + FLOOR_CLEARANCE_M, float(first[:, 2].min()), float(last[:, 2].min()))
    lo, hi = np.array([-np.inf, -np.inf, bottom]), np.full(3, np.inf)
    limits = replace(limits, geofence_min_m=lo, geofence_max_m=hi)  # the floor: no drone pushed into it
    keep = 0.0 if limits.d_min_m is None else limits.d_min_m + 2.0 * limits.tracking_m
    pads = None
    if pads_m is None:
        up, down = (ground_layout(x[:, :2], LAYOUT_SPACING * keep) for x in (first, last))
    else:
        pads, landing = (pad_layout(x[:, :2], pads_m, keep) for x in (first, last))
        up, down = pads_m[pads], pads_m[landing]
    lift = np.column_stack([up, np.full(up.shape[0], hover)])
    land = np.column_stack([down, np.full(down.shape[0], hover)])
    ascent = plan_phase(lift, first, dt_s, limits, "ascent")
    descent = plan_phase(last, land, dt_s, limits, "descent")
    path = np.concatenate([ascent[:-1], mission_m, descent[1:]])
    a, b = ascent.shape[0] - 1, ascent.shape[0] - 2 + mission_m.shape[0]  # the mission's first, last
    phases = [("ascent", slice(0, a + 1))] if a else []
    phases.append(("mission", slice(a, b + 1)))
    if descent.shape[0] > 1 and np.any(descent[-1] != descent[0]):
        phases.append(("descent", slice(b, path.shape[0])))
    takeoff_s = vertical_leg_s(hover - floor_m, flight_limits)
    return Flight(path, dt_s, tuple(phases), up, down, floor_m, hover, takeoff_s, takeoff_s, pads)


def phase_record(
    flight: Flight, parts: list[PhasePieces], limits: FlightLimits, metric: Array | None = None
) -> dict[str, Any]:
    """Per phase (takeoff, the exported ``parts``, landing): duration [s], peak speed [m/s],
    acceleration [m/s^2] and jerk [m/s^3], and the closest two drones [m] of its pieces (in the
    downwash ``metric`` when given); for the retimed ones ``min_time_s``, a lower bound on their
    duration (:func:`mpcform.outputs.flight.retime.minimum_time_s`), and ``slow_end_s``, how long
    the phase ends with every drone below :data:`SLOW_SHARE` of the speed limit."""
    h = flight.hover_m - flight.floor_m
    out: dict[str, Any] = {"takeoff": _leg(flight.takeoff_s, h, flight.takeoff_xy_m)}
    for part in parts:
        poly = part.flown
        t = np.linspace(0.0, poly.duration_s, int(np.ceil(CHECK_RATE_HZ * poly.duration_s)) + 1)
        state = flat_state(poly, t, flight.positions_m.shape[1])
        peaks = {key: float(np.linalg.norm(state[s], axis=-1).max()) for key, s in _PEAKS}
        scaled = state["pos"] if metric is None else state["pos"] * metric
        sep = float(min_pair_distances(scaled).min()) if state["pos"].shape[1] > 1 else None
        fast = np.nonzero(
            np.linalg.norm(state["vel"], axis=-1).max(axis=1) >= SLOW_SHARE * limits.max_speed_mps
        )[0]
        out[part.name] = {
            "duration_s": poly.duration_s,
            "min_time_s": part.min_time_s,
            "slow_end_s": float(t[-1] - t[fast[-1]]) if fast.size else poly.duration_s,
            "pieces": poly.pieces,
            **peaks,
            "min_separation_m": sep,
        }
    return out | {"landing": _leg(flight.land_s, h, flight.landing_xy_m)}


_PEAKS = (("max_speed_mps", "vel"), ("max_acc_mps2", "acc"), ("max_jerk_mps3", "jerk"))


def _leg(duration_s: float, height_m: float, xy_m: Array) -> dict[str, Any]:
    """A vertical leg's record: duration, the septic profile's peaks, the layout's closest pair."""
    v, a, j = (p * height_m / duration_s**r for r, p in enumerate(LEG_PEAKS, start=1))
    sep = float(min_pair_distances(xy_m[None])[0]) if xy_m.shape[0] > 1 else None
    return {
        "duration_s": duration_s,
        "max_speed_mps": v,
        "max_acc_mps2": a,
        "max_jerk_mps3": j,
        "min_separation_m": sep,
    }
