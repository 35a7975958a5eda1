"""Certification of a command, and the safe fallback when a solve fails or does not certify.

A command is certified when it lies in the ball ``||u_i|| <= v_max`` (it is scaled into it,
eq. 7; with ``limits.v_max_z``, into the spheroid ``||S u_i|| <= v_max`` inside it) and, along
the first segment ``p0 -> p0 + dt u``, no pair (or drone-obstacle item) within reach gets
closer than ``d_min`` (its required distance), or than it already was. With a velocity loop
(:mod:`mpcform.mpc.velocity_loop`) the segment ends where the loop takes the drone,
``p0 + dt u + F_1 xi_0 + G_{1,0} u`` (the chord of the interval's true motion), and an item inside
its distance may also come as close as the hold's chord ``p0 -> p0 + F_1 xi_0`` takes it: within
the interval no command undoes the velocity a drone already has (the QP's no-approach rows leave
out that free response too).

The fallback, when a solve fails or does not certify, is the first of these
that certifies: the previous plan's next input (with braking, the plan's braking tail,
:mod:`mpcform.mpc.constraints.braking`, which the theorem there certifies when the drones followed the plan);
the solved command scaled back (1, 1/2, 1/4, 1/8: certification is monotone in the scale, the
scaled segment being part of the full one); a separating command (each drone inside a required
distance flies away from its close partners and obstacles, scaled back the same way); with
``a_max``, a step that decelerates within ``a_max dt``; a hold (which never brings two drones
closer). With ``a_max`` every candidate is first moved into the box ``|u - u_prev| <= a_max dt``
(a plant margin assumes command changes within it), and when none certifies the last resort is
the plan's tail (or a decelerating step), reported uncertified, never a jump to a hold. So the
planning loop never raises or returns NaN for a solver's failure, and a pair
that starts too close separates even when the QP fails.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mpcform._validate import Array
from mpcform.control.laws import saturate
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.candidates import Candidates
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.plan import Plan
from mpcform.mpc.safety.first_rows import hard_first_rows

CERTIFY_TOL_M = 1e-7  # separation certification tolerance [m]


class Certifier:
    """Certifies first inputs against the ball of radius ``v_max_mps`` (squeezed along the axes by
    ``scale``, :meth:`mpcform.world.limits.Limits.speed_scale`) and the ``separation`` items."""

    def __init__(
        self,
        dt_s: float,
        v_max_mps: float | None,
        separation: Separation,
        a_max_mps2: float | None = None,
        braking: Braking | None = None,
        scale: Array | None = None,
    ) -> None:
        self.dt_s, self.v_max_mps, self.separation, self.braking = dt_s, v_max_mps, separation, braking
        self.scale = None if scale is None or np.all(scale == 1.0) else scale  # None: the ball
        self.a_step_mps = None if a_max_mps2 is None else a_max_mps2 * dt_s  # largest change per step
        self.drift: Callable[[Array], Array] | None = None
        """With a velocity loop: where a command takes the drones beyond ``dt u`` in the interval."""
        self.rest_command: Callable[[], Array] | None = None
        """With a velocity loop: the command (n, d) the drones rest at (``-delta``), which the
        previous plan's braking tail brakes towards (:meth:`Braking.shifted`)."""
        self.floor_command: Array | None = None
        """With a velocity loop: the braking command (n, d) whose chord sets the floor (the one the
        QP's first rows are lowered to, :func:`mpcform.mpc.safety.first_rows.hard_first_rows`; None: the
        hold)."""

    def certify(self, p0: Array, u: Array, cand: Candidates, u_prev: Array | None = None) -> Array | None:
        """The command ``u`` (n, d) scaled into the ball (with ``u_prev`` and ``a_max``, first moved
        into the box ``|u - u_prev| <= a_max dt``: the solver's tolerance off), if it is safe from
        ``p0`` (n, d), else None."""
        u0 = self.saturate(u) if u_prev is None else self.within_limits(u, u_prev)
        return u0 if self.safe(p0, u0, cand) else None

    def safe(self, p0: Array, u0: Array, cand: Candidates) -> bool:
        """Along ``p0 -> p0 + dt u0`` (with a loop, its true chord) no item within reach gets
        closer than required, or than it already was, or (with a loop) than the braking command's
        chord takes it (:attr:`floor_command`) (up to :data:`CERTIFY_TOL_M`)."""
        p1, free = p0 + self.dt_s * u0, None
        if self.drift is not None:
            p1 = p1 + self.drift(u0)
            brake = np.zeros_like(u0) if self.floor_command is None else self.floor_command
            free = self.separation.first_segment(p0, p0 + self.dt_s * brake + self.drift(brake), cand)
        for j, (start, along, required) in enumerate(self.separation.first_segment(p0, p1, cand)):
            floor = np.minimum(required, start)
            if free is not None:  # as close as the free response takes it
                floor = np.minimum(floor, free[j][1])
            if np.any(along < floor - CERTIFY_TOL_M):
                return False
        return True

    def fallback(
        self,
        plan: Plan | None,
        p0: Array,
        cand: Candidates,
        horizon: int,
        solved: Array | None = None,
        u_prev: Array | None = None,
    ) -> tuple[Array, Array, str]:
        """Inputs (H, n, d), relative positions and a status note: the first certified of the
        previous plan's next input, the ``solved`` command (n, d) or a separating command scaled
        back, a decelerating step (with ``a_max``), else a hold. ``u_prev`` (n, d): the last command."""
        prev = np.zeros_like(p0) if u_prev is None else u_prev
        if plan is not None:
            u_plan = self.tail(plan, prev)
            if u_plan[0].any() and self.safe(p0, u_plan[0], cand):  # (a hold comes last)
                return u_plan, self.dt_s * np.cumsum(u_plan, axis=0), "previous plan"
        push = (self.v_max_mps or 1.0) * self.separation.push_apart(p0, cand)
        tries = [("solved command", solved), ("separating command", push)]
        for note, base in tries:
            if base is None or not base.any():
                continue
            for scale in SCALES:
                u0 = self.within_limits(scale * base, prev)
                if self.safe(p0, u0, cand):
                    return self.hold_after(u0, horizon, f"{note} x {scale:g}")
        if self.a_step_mps is not None and prev.any():
            u0 = self.within_limits(np.zeros_like(prev), prev)
            if self.safe(p0, u0, cand):
                return self.hold_after(u0, horizon, "decelerate")
            if plan is not None:  # no jump the drones cannot follow: the plan's braking tail
                u_plan = self.tail(plan)
                return u_plan, self.dt_s * np.cumsum(u_plan, axis=0), "previous plan (uncertified)"
            return self.hold_after(u0, horizon, "decelerate (uncertified)")
        hold = np.zeros((horizon,) + p0.shape)
        return hold, hold, "hold"

    def kept(
        self,
        plan: Plan | None,
        p0: Array,
        cand: Candidates,
        u_prev: Array,
        meets: Callable[[Array, Array], bool],
    ) -> tuple[Array, Array] | None:
        """With braking, the previous ``plan`` shifted (inputs, relative positions) if it ``meets``
        this step's rows and its first input (within ``a_max dt`` of ``u_prev``) certifies, else
        None: theorem (ii) of :mod:`mpcform.mpc.constraints.braking` makes it feasible for the drones that
        followed it, so a solve that left slack it avoids (an interior-point solver can) gives way."""
        if plan is None or self.braking is None:
            return None
        u = self.tail(plan, u_prev)
        x = self.dt_s * np.cumsum(u, axis=0)
        return (u, x) if meets(u, x) and self.safe(p0, u[0], cand) else None

    def hard_first_rows(
        self, rows: SeparationRows, plan: Plan | None, u_prev: Array, horizon: int, forced_m: Array
    ) -> tuple[SeparationRows, bool, Array]:
        """Under a velocity loop (``forced_m`` (d,): its first interval's forced response per m/s),
        the QP's ``rows`` with every first row hard, lowered at most to where braking (the last
        command ``u_prev`` moved towards zero by ``a_max dt``, or zero) or, with the braking tail,
        the previous ``plan``'s next input takes the drones (whichever needs less lowering: the
        plan's when the drones followed it, :mod:`mpcform.mpc.constraints.braking`)
        (:func:`mpcform.mpc.safety.first_rows.hard_first_rows`); also whether a bound was lowered, and
        that braking plan (H, n, d), whose first chord becomes :attr:`floor_command`."""
        plans = self.braking_plans(plan, u_prev, horizon)
        first = np.stack([u[0] for u in plans])
        hard, relaxed, best = hard_first_rows(rows, (self.dt_s + forced_m) * first)
        self.floor_command = first[best]  # the rows allow its chord, so must the certifier
        return hard, relaxed, plans[best]

    def braking_plans(self, plan: Plan | None, u_prev: Array, horizon: int) -> list[Array]:
        """Plans (H, n, d) that need no solve, from the last command ``u_prev``: decelerating by
        ``a_max dt`` per step to a hold, then with braking the previous ``plan``'s tail (its first
        input moved within ``a_max dt`` of ``u_prev``)."""
        plans = [self.hold_after(self.within_limits(np.zeros_like(u_prev), u_prev), horizon, "")[0]]
        if self.braking is not None and plan is not None:
            plans.append(self.tail(plan, u_prev))
        return plans

    def tail(self, plan: Plan, u_prev: Array | None = None) -> Array:
        """The previous plan's inputs shifted one step, its last braking
        (:mod:`mpcform.mpc.constraints.braking`;
        without braking, slowing by ``a_max dt`` or, without ``a_max``, holding); with the last
        command ``u_prev``, the first moved within ``a_max dt`` of it (the solver's tolerance off)."""
        if self.braking is not None:
            rest = None if self.rest_command is None else self.rest_command()
            u = self.braking.shifted(plan.inputs_mps, rest)
        else:
            u = plan.shifted_inputs(self.a_step_mps)
        if u_prev is not None:
            u[0] = self.within_limits(u[0], u_prev)
        return u

    def within_limits(self, u: Array, u_prev: Array) -> Array:
        """``u`` (n, d) moved into the box ``|u - u_prev| <= a_max dt`` (with ``a_max``), then
        scaled into the ball."""
        if self.a_step_mps is not None:
            u = u_prev + np.clip(u - u_prev, -self.a_step_mps, self.a_step_mps)
        return self.saturate(u)

    def saturate(self, u: Array) -> Array:
        """``u`` (n, d) scaled into the ball (eq. 7), or the spheroid ``||S u|| <= v_max``."""
        if self.scale is None or self.v_max_mps is None:
            return saturate(u, self.v_max_mps)
        return saturate(u * self.scale, self.v_max_mps) / self.scale

    def hold_after(self, u0: Array, horizon: int, note: str) -> tuple[Array, Array, str]:
        """The plan ``u0`` then slowing to a hold (within ``a_max dt`` per step with ``a_max``)."""
        u = np.zeros((horizon,) + u0.shape)
        u[0] = u0
        if self.a_step_mps is not None:
            for j in range(1, horizon):
                u[j] = u[j - 1] - np.clip(u[j - 1], -self.a_step_mps, self.a_step_mps)
        return u, self.dt_s * np.cumsum(u, axis=0), note


SCALES = (1.0, 0.5, 0.25, 0.125)  # fractions of a fallback command tried, largest first
