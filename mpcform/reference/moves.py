"""One move between two keyframes: a rest-to-rest, jerk-limited, time-optimal ruckig trajectory.

A move is ONE offline ruckig trajectory with phase synchronisation over the degrees of freedom

    x = (c [m] (d), phi [rad], s, alpha)

from rest to rest (zero velocity and acceleration at both ends); ``phi`` is the geodesic angle
of the turn (:func:`turn`) and ``alpha`` the progress of a template switch. ruckig's
intermediate waypoints are never used (the community build sends them to a cloud service).

Limits (:func:`dof_limits`): explicit bounds per DOF group (:class:`MissionLimits`) and/or a
:class:`SpeedBudget` derived from the drones' v_max; where both apply the smaller wins. With a
budget, every drone's reference speed ``||c_dot|| + |s_dot| |rho_i| + s |omega| |rho_i| + s
|alpha_dot| |r'_i - r_i|`` (an upper bound of ``||p_dot*_i||``) stays below ``V = fraction * v_max``:

* With phase synchronisation every DOF follows one normalised profile ``x_k(t) = x_k0 +
  Delta_k f(t)``, ``f: 0 -> 1``, so the speed bound of drone i is ``f_dot(t) K_i`` with ``K_i =
  ||Delta c|| + (|Delta s| + s_hi |Delta phi|) m_i + s_hi |Delta alpha| b_i`` (``s_hi`` the larger
  end scale, ``m_i = max(|rho_i|)`` over both ends, ``b_i = |r'_i - r_i|``).
* The budget is split between the DOFs in proportion to their share of ``K = max_i K_i``: DOF k
  gets ``v_k = |Delta_k| V / K`` (acceleration ``|Delta_k| A / K``, jerk ``|Delta_k| J / K``),
  i.e. every DOF the same normalised rate, so all of them saturate together and ``f_dot <= V /
  K`` is exactly the time-optimal profile under the bound. The centroid's share is spread over
  its axes along ``Delta c`` (``|Delta c_j| V / K``), so its speed ``||c_dot||`` meets its share,
  not ``sqrt(d)`` times it. (Each DOF within its own limit keeps the bound even without phase
  synchronisation.)
* The acceleration and jerk budgets bound the along-path part ``f_ddot K_i`` (``f_dddot K_i``);
  the product terms of rotation and scaling (centripetal ``s |omega|^2 |rho|``, ``2 s_dot omega x
  q``) are not included.

Explicit centroid limits bound the norm the same way (per-axis limits along ``Delta c``). A
DOF that moves no drone (zero offsets) gets a lever arm of 1 m.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ruckig import InputParameter, Result, Ruckig, RuckigError, Synchronization, Trajectory

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.formation.rotation import geodesic
from mpcform.reference.keyframes import GROUPS, KEYFRAME_FIELDS, MissionLimits, SpeedBudget

SNAP_RTOL = 1e-12
"""Displacements below ``SNAP_RTOL * max(1, |start|, |end|)`` count as zero (no motion)."""
HALF_TURN_TOL = 1e-9
"""Turns within this of pi [rad] are exactly half a turn: the axis is chosen deterministically."""


def turn(r0: Array, r1: Array) -> tuple[Array, float]:
    """Geodesic axis and angle; exactly half a turn gets a deterministic axis (+z planar: +1)."""
    axis, phi = geodesic(r0, r1)
    if abs(phi - np.pi) > HALF_TURN_TOL:
        return axis, phi
    if r0.shape == (2, 2):
        return np.array([1.0]), float(np.pi)
    outer = (r0.T @ r1 + np.eye(3)) / 2.0  # = a a^T for a half turn about a
    j = int(np.argmax(np.diag(outer)))
    a = outer[:, j] / np.linalg.norm(outer[:, j])
    lead = a[np.flatnonzero(np.abs(a) > 1e-9)[0]]
    return a * np.sign(lead), float(np.pi)


def dof_limits(
    x0: Array, x1: Array, offsets0: Array, offsets1: Array, limits: MissionLimits, budget: SpeedBudget | None
) -> list[Array]:
    """Velocity, acceleration and jerk limit per DOF of the move ``x0 -> x1`` (the budget split above).

    ``offsets0`` and ``offsets1`` (n, d) are the drones' template offsets at both ends.
    """
    d = offsets0.shape[1]
    delta = np.abs(x1 - x0)
    dc = float(np.linalg.norm(delta[:d]))
    lever = np.maximum(np.linalg.norm(offsets0, axis=1), np.linalg.norm(offsets1, axis=1))
    swing = np.linalg.norm(offsets1 - offsets0, axis=1)
    s_hi = max(x0[d + 1], x1[d + 1])
    k_i = dc + (delta[d + 1] + s_hi * delta[d]) * lever + s_hi * delta[d + 2] * swing
    k_max = float(k_i.max())
    unit = dc + delta[d + 1] + s_hi * delta[d] + s_hi * delta[d + 2]  # with a 1 m lever arm
    if k_max <= SNAP_RTOL * unit:
        k_max = unit
    groups = _dof_groups(d)
    # direction share of the centroid's norm bound, 1 for the scalar DOFs
    share = np.ones_like(delta)
    if dc > 0:
        share[:d] = delta[:d] / dc
    moving = delta > 0
    out = []
    for kind in range(3):
        explicit = np.array([limits.get(kind, g) for g in groups])
        explicit[moving] *= share[moving]
        derived = np.full_like(delta, np.inf)
        if budget is not None:
            derived = delta * (budget.budgets[kind] / k_max)
        lim = np.minimum(explicit, derived)
        out.append(np.where(moving, lim, 1.0))
    return out


def plan_move(
    k: int,
    x0: Array,
    x1: Array,
    offsets0: Array,
    offsets1: Array,
    limits: MissionLimits,
    budget: SpeedBudget | None,
) -> Any:
    """The ruckig trajectory of the move to keyframe ``k``; errors name the keyframe's field."""
    name = f"reference.keyframes[{k}]"
    groups = _dof_groups(offsets0.shape[1])
    with np.errstate(all="ignore"):
        vel, acc, jerk = dof_limits(x0, x1, offsets0, offsets1, limits, budget)
    for kind, lim in zip(("max_velocity", "max_acceleration", "max_jerk"), (vel, acc, jerk), strict=True):
        bad = np.flatnonzero(~np.isfinite(lim) | (lim <= 0))
        if bad.size:
            g = groups[bad[0]]
            if not np.isinf(lim[bad[0]]):
                raise ValidationError(
                    f"{name}.{KEYFRAME_FIELDS[g]}",
                    f"the move gives a degenerate {kind} limit {lim[bad[0]]:g} for the {g} DOF",
                )
            raise ValidationError(
                f"reference.{kind}.{g}",
                f"keyframe {k} moves the {g} DOF but no limit is set for it: set "
                f"limits.v_max (derived limits) or reference.{kind}.{g}",
            )
    traj, problem = _ruckig(x0, x1, vel, acc, jerk)
    if traj is None:
        group = _failing_group(x0, x1, vel, acc, jerk, groups)
        where = name if group is None else f"{name}.{KEYFRAME_FIELDS[group]}"
        raise ValidationError(
            where,
            f"ruckig cannot plan the move to this keyframe ({problem}); check the keyframe's "
            "values and the limits",
        )
    return traj


def _dof_groups(dim: int) -> list[str]:
    """The group of each DOF of ``x = (c (d), phi, s, alpha)``."""
    return ["centroid"] * dim + ["rotation", "scale", "blend"]


def _ruckig(x0: Array, x1: Array, vel: Array, acc: Array, jerk: Array) -> tuple[Any, str]:
    """Offline rest-to-rest trajectory with phase synchronisation, or (None, the problem)."""
    dofs = x0.shape[0]
    inp = InputParameter(dofs)
    inp.current_position, inp.target_position = x0.tolist(), x1.tolist()
    inp.current_velocity = inp.current_acceleration = [0.0] * dofs
    inp.target_velocity = inp.target_acceleration = [0.0] * dofs
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = vel.tolist(), acc.tolist(), jerk.tolist()
    inp.synchronization = Synchronization.Phase
    traj = Trajectory(dofs)
    try:
        result = Ruckig(dofs).calculate(inp, traj)
    except RuckigError as exc:
        return None, str(exc).strip().splitlines()[0] if str(exc).strip() else "RuckigError"
    except ValueError as exc:  # result codes the binding's enum lacks (-101: duration too long)
        return None, f"ruckig result {exc}"
    if result != Result.Working:
        return None, f"result {result.name}"
    if not np.isfinite(traj.duration) or traj.duration < 0:
        return None, f"duration {traj.duration}"
    end = np.asarray(traj.at_time(traj.duration)[0])
    if not np.all(np.isfinite(end)) or np.abs(end - x1).max() > 1e-6 * max(1.0, float(np.abs(x1).max())):
        return None, "the trajectory does not reach the keyframe"
    return traj, ""


def _failing_group(
    x0: Array, x1: Array, vel: Array, acc: Array, jerk: Array, groups: list[str]
) -> str | None:
    """The first DOF group that ruckig cannot plan on its own (to name the keyframe's field)."""
    names = np.array(groups)
    for g in GROUPS:
        sel = names == g
        if np.any(x1[sel] != x0[sel]) and _ruckig(x0[sel], x1[sel], vel[sel], acc[sel], jerk[sel])[0] is None:
            return g
    return None
