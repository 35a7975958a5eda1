"""Certification of a command, and the safe fallback when a solve fails or does not certify.

A command is certified when it lies in the ball ``||u_i|| <= v_max`` (it is scaled into it,
eq. 7) and, along the first segment ``p0 -> p0 + dt u``, no pair (or drone-obstacle item) within
reach gets closer than ``d_min`` (its required distance), or than it already was. The fallback is
the previous plan's next input, scaled into the ball, if it certifies, else every drone holding;
so the planning loop never raises or returns NaN for a solver's failure.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.control.laws import saturate
from mpcform.formation.geometry import closest_on_segments
from mpcform.mpc.candidates import Candidates
from mpcform.mpc.plan import Plan
from mpcform.mpc.separation import Separation

CERTIFY_TOL_M = 1e-7  # separation certification tolerance [m]


class Certifier:
    """Certifies first inputs against the ball of radius ``v_max_mps`` and the ``separation`` items."""

    def __init__(self, dt_s: float, v_max_mps: float | None, separation: Separation) -> None:
        self.dt_s, self.v_max_mps, self.separation = dt_s, v_max_mps, separation

    def certify(self, p0: Array, u: Array, cand: Candidates) -> Array | None:
        """The command ``u`` (n, d) scaled into the ball, if it is safe from ``p0`` (n, d), else None."""
        u0 = saturate(u, self.v_max_mps)
        return u0 if self.safe(p0, u0, cand) else None

    def safe(self, p0: Array, u0: Array, cand: Candidates) -> bool:
        """Along ``p0 -> p0 + dt u0`` no item within reach gets closer than required, or than it
        already was (up to :data:`CERTIFY_TOL_M`)."""
        p1 = p0 + self.dt_s * u0
        for a, b, required in self.separation.first_segment(p0, p1, cand):
            d_seg = np.linalg.norm(closest_on_segments(a, b), axis=1)
            if np.any(d_seg < np.minimum(required, np.linalg.norm(a, axis=1)) - CERTIFY_TOL_M):
                return False
        return True

    def fallback(
        self, plan: Plan | None, p0: Array, cand: Candidates, horizon: int
    ) -> tuple[Array, Array, str]:
        """Inputs (H, n, d), relative positions and a status note: the previous plan's next input
        (scaled into the ball) if it certifies, else a hold."""
        if plan is not None:
            u_plan = plan.shifted_inputs()
            u_plan[0] = saturate(u_plan[0], self.v_max_mps)
            if self.safe(p0, u_plan[0], cand):
                return u_plan, self.dt_s * np.cumsum(u_plan, axis=0), "previous plan"
        hold = np.zeros((horizon,) + p0.shape)
        return hold, hold, "hold"
