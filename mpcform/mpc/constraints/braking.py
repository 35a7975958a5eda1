r"""The braking terminal condition: every plan ends where each drone can still stop.

With ``a_max`` every plan is continued past its horizon by *geometric braking*,
``u_{H-1+m} = rho^m u_{H-1}`` with ``rho = max(0, 1 - a_max dt / v_max)``, and its separation
rows cover one more segment, from ``x_H`` to the *stop point*

.. math::
    x_{stop} = x_H + \kappa\, u_{H-1}, \qquad \kappa = dt\, \rho / (1 - \rho) = v_{max}/a_{max} - dt
    \quad (\kappa = 0 \text{ when } a_{max} dt \ge v_{max}).

**Theorem (recursive feasibility).** Assume the drones move as the planner models them (the
single integrator, or the modelled velocity loop with a unit DC gain) up to the margin, every
command lies in the velocity set (so ``|u_a| <= v_max`` per component) and the acceleration rows
``|u_j - u_{j-1}| <= a_max dt`` hold. If a step's plan meets its rows, then (i) the plan followed
by its braking keeps every pair ``d_min`` apart and every drone clear of its obstacles, all the
way to rest, and (ii) the shifted plan ``(u_1 .. u_{H-1}, rho u_{H-1})`` meets the next step's
rows without slack: it is a feasible, certified fallback.

*Proof.* The tail changes each component by ``(1 - rho) rho^{m-1} |u_{H-1,a}| <= (1 - rho) v_max
<= a_max dt`` and stays in the convex velocity set (a scaling towards 0). Its positions are
``x_H + s_m u_{H-1}`` with ``s_m = dt sum_{l<=m} rho^l`` in ``[0, kappa]``, the same ``s_m`` for
every drone, so each drone's tail and each pair's relative tail lie on the segment from the
values at ``x_H`` to those at ``x_stop``; a row at both ends of that segment with the segment's
normal (:mod:`mpcform.mpc.constraints.separation`) holds along it, and its half-space excludes the forbidden
ball, which proves (i). Geometric braking is shift-invariant: the shifted plan's own tail is
the old tail, so its whole path is part of the old one and keeps ``d_min``; the next rows are
linearised about it (their normals point at the closest point of each guess segment), so it
meets them, and the velocity, acceleration (first change ``u_1 - u_0``, last ``(rho - 1)
u_{H-1}``) and geofence rows (a box is convex) as well, which proves (ii).

With a velocity loop the stop point is where the loop comes to rest,
``g (x_H + kappa u_{H-1}) + F_rest xi_0`` (``g`` the loop's DC gain, ``F_rest`` its free response
at rest, :class:`mpcform.mpc.velocity_loop.VelocityLoop`), and the true path from ``y_H`` to it is curved
(an underdamped loop overshoots it). The tail's rows then sit at ``y_H``, at the vertices of a
polytope that holds the whole path to rest and maps into itself under the shift (after a few
exact points of the path where the polytope alone would be much wider), and at the rest point,
one normal per item (:mod:`mpcform.mpc.constraints.tail`): (i) and (ii) hold as above, with "the
segment" read as that polytope. Its vertices carry one set of weights for every axis: the axes
share one loop (a lag, the second-order loop, a planar quadrotor), or their groups' polytopes
are built together (a spatial quadrotor's xy and z loops). A quadrotor's polytope is tight only
after many exact points, whose rows a joint QP cannot afford: there the rows stay on the chord
to the rest point (:data:`mpcform.mpc.constraints.tail.SAMPLED_STATES`), and the margin has to cover the
path's bend. With the loop's velocity offset ``delta`` (persistent over the plan,
:mod:`mpcform.mpc.velocity_loop`) the plan is the same in the velocity over ground ``u + delta``: it
brakes that geometrically, its commands towards ``-delta`` (:meth:`Braking.shifted`,
:func:`mpcform.mpc.constraints.tail.with_offset`), and (i) and (ii) hold for a constant ``delta``;
the tail's commands may then leave the velocity set by ``|delta|`` and change by up to
``(1 - rho) (v_max + |delta|)`` per step (they have no rows). A change of the estimate moves the
plan like a push. Wind moves the measured start, and with it the shifted plan, beyond (i): in wind the
rows grow along the horizon (:func:`mpcform.mpc.constraints.rows.step_growth`), which keeps the shifted plan
feasible for pushes within the growth up to its window; past the window a plan may reach into
the growth (a buffer, reported apart from slack: :func:`mpcform.mpc.safety.slack.slack_report`); beyond
that the planner reports slack, and the certifier (:mod:`mpcform.mpc.safety.certify`) still guards the
first interval.
When a solve leaves slack on rows the shifted plan meets (an interior-point solver can), the
planner keeps the shifted plan, as (ii) allows (:meth:`mpcform.mpc.planner.MPCPlanner.step`).

The stop point adds no speed cap (the stop lies past the horizon), but it is conservative:
``kappa |u|`` is up to twice the shortest braking distance ``|u|^2 / (2 a_max)`` at ``v_max``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.world.bounds import PlanningBounds

MAX_STOP_M = 1e6
"""The longest braking distance ``v_max^2 / (2 a_max)`` taken [m] (a scenario's extent bound too):
beyond it the stop points are numbers no QP can use, and no drone brakes over 1000 km."""


@dataclass(frozen=True)
class Braking:
    """Geometric braking past the horizon: ``rho`` per step, stop point ``x_H + kappa_s u_{H-1}``."""

    dt_s: float
    rho: float
    kappa_s: float

    @classmethod
    def of(cls, dt_s: float, limits: PlanningBounds, enabled: bool = True) -> Braking | None:
        """The braking of ``limits`` (None without a finite ``a_max`` and ``v_max``, or when
        ``enabled`` is False: :attr:`mpcform.mpc.settings.MPCSettings.braking`)."""
        a_max, v_max = limits.a_max_mps2, limits.v_max_mps
        if not enabled or a_max is None or v_max is None or not np.isfinite(a_max):
            return None
        if v_max**2 / (2.0 * a_max) > MAX_STOP_M:
            raise ValidationError(
                "limits.v_max",
                f"braking from {v_max:.3g} m/s at a_max = {a_max:.3g} m/s^2 would take "
                f"{v_max**2 / (2.0 * a_max):.3g} m; expected a speed a drone stops from within "
                f"{MAX_STOP_M:g} m (or controller.braking = false)",
            )
        rho = max(0.0, 1.0 - a_max * dt_s / v_max)
        return cls(dt_s, rho, dt_s * rho / (1.0 - rho))

    def stop(self, x_last: Array, u_last: Array) -> Array:
        """Stop points (n, d) of plans ending at ``x_last`` with the last inputs ``u_last`` (n, d)."""
        return x_last + self.kappa_s * u_last

    def shifted(self, u: Array, rest_mps: Array | None = None) -> Array:
        """Inputs (H, n, d) shifted one step, the last one braking: ``(u_1 .. u_{H-1}, rho u_{H-1})``;
        with ``rest_mps`` (n, d), the command a drone rests at (``-delta``, the velocity offset of
        :mod:`mpcform.mpc.velocity_loop`), braking towards it: ``rest + rho (u_{H-1} - rest)``."""
        if rest_mps is None:
            return np.concatenate([u[1:], self.rho * u[-1:]])
        return np.concatenate([u[1:], (rest_mps + self.rho * (u[-1] - rest_mps))[None]])
