"""The limit families a planner's limits ask for, in the QP's row order, and what they answer
together: the drones a plan breaks them for, and the geofence's free response widened to admit a
braking plan, turned back into the fence first (:mod:`mpcform.mpc.constraints.family`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.acceleration import AccelerationRows
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.geofence import GeofenceRows
from mpcform.mpc.constraints.rows import step_growth
from mpcform.mpc.constraints.tail import planner_tail
from mpcform.mpc.constraints.velocity import VelocityRows
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.world.bounds import PlanningBounds


def limit_rows(
    dim: int, dt_s: float, limits: PlanningBounds, settings: MPCSettings, loop: VelocityLoop | None = None
) -> tuple[LimitRows, ...]:
    """The families the limits ask for, in the QP's row order: velocity, acceleration, geofence
    (on the ``loop``'s positions with one; shrunk along the horizon by the rows' growth,
    :func:`mpcform.mpc.constraints.rows.step_growth`)."""
    h = settings.horizon
    families: list[LimitRows] = []
    if limits.v_max_mps is not None:
        families.append(VelocityRows(dim, h, settings, limits.v_max_mps, limits.speed_scale(dim)))
    if limits.a_max_mps2 is not None:
        families.append(AccelerationRows(dim, h, dt_s, limits.a_max_mps2))
    if limits.geofence_min_m is not None and limits.geofence_max_m is not None:
        fence = limits.geofence_min_m, limits.geofence_max_m
        braking = Braking.of(dt_s, limits, settings.braking)
        tail = planner_tail(braking, settings, dim, loop)
        growth = step_growth(limits.growth_m, dt_s, h, 0 if tail is None else tail.count)
        families.append(GeofenceRows(dim, h, dt_s, *fence, settings.margin_m, tail, loop, growth))
    return tuple(families)


def violators(
    families: tuple[LimitRows, ...], p0: Array, u_prev: Array, u: Array, x: Array, tol: float = 0.0
) -> Array:
    """Drones (n,) whose ``(u, x)`` miss a velocity, acceleration or geofence row by more than ``tol``."""
    if len(families) == 1:
        return families[0].violators(p0, u_prev, u, x, tol)
    bad = np.zeros(p0.shape[0], dtype=bool)
    for family in families:
        bad |= family.violators(p0, u_prev, u, x, tol)
    return bad


def admitted(families: tuple[LimitRows, ...], p0: Array, free_m: Array, path_m: Array) -> Array:
    """The free response ``free_m`` (S, n, d) the geofence's bounds are written with, moved so that
    from the second position on they admit ``path_m`` (S, n, d), where a plan that needs no solve
    takes the drones (:meth:`mpcform.mpc.safety.certify.Certifier.braking_plans`): wind the loop did not
    foresee can leave no plan inside the fence, and the QP stays feasible (as the first rows, whose
    bounds are lowered to the same plan). Without a geofence: ``free_m``."""
    fence = next((f for f in families if isinstance(f, GeofenceRows)), None)
    if fence is None:
        return free_m
    lo, hi = fence.box(p0)
    if lo.ndim == 3:  # with the rows' growth: one box per bounded position
        lo, hi = lo[1:], hi[1:]
    out = free_m.copy()
    forced = path_m[1:] - free_m[1:]
    out[1:] = np.clip(free_m[1:], lo - forced, hi - forced)
    return out


def inwards(families: tuple[LimitRows, ...], p0: Array, path_m: Array) -> Array:
    """Which way (n, d) each drone's ``path_m`` (S, n, d) must turn on each axis to stay in the
    geofence's box from the second position on: +1 where it leaves the box below, -1 above, 0
    where it does neither (or both; everywhere without a geofence)."""
    fence = next((f for f in families if isinstance(f, GeofenceRows)), None)
    if fence is None:
        return np.zeros(path_m.shape[1:])
    lo, hi = fence.box(p0)
    if lo.ndim == 3:
        lo, hi = lo[1:], hi[1:]
    below, above = (path_m[1:] < lo).any(axis=0), (path_m[1:] > hi).any(axis=0)
    return below.astype(float) - above.astype(float)


def turned_inwards(
    plan_mps: Array,
    u_prev_mps: Array,
    rest_mps: Array,
    inward: Array,
    a_step_mps: float,
    within_limits: Callable[[Array, Array], Array],
) -> Array:
    """The braking ``plan_mps`` (H, n, d) turned back into the fence on the axes ``inward`` (n, d)
    names (:func:`inwards`): there the commands move by ``a_step_mps`` a step, from the last command
    ``u_prev_mps``, towards the rest command ``rest_mps`` (n, d) (the velocity offset cancelled) plus
    one step inwards, each step moved by ``within_limits`` (the command-change box, the velocity
    set). Braking along a velocity offset (a Crazyflie's sag at speed) keeps a drone sinking out of
    the fence; this plan stops it and climbs back."""
    turn, want = inward != 0.0, rest_mps + a_step_mps * inward
    out, prev = plan_mps.copy(), u_prev_mps
    for j in range(plan_mps.shape[0]):
        out[j] = prev = within_limits(np.where(turn, want, plan_mps[j]), prev)
    return out
