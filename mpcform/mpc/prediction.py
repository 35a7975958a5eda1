"""Where a plan takes the drones: the single integrator, the velocity loop's offsets
(:mod:`mpcform.mpc.loop`) and the braking tail's stop point (:mod:`mpcform.mpc.braking`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.braking import Braking
from mpcform.mpc.loop import VelocityLoop
from mpcform.mpc.plan import Plan, guess
from mpcform.mpc.separation import SeparationRows


class Prediction:
    """The positions the separation rows and tests are written on, for drones in loop ``state``
    (n, d, s) (no states without a ``loop``): steps 1..H, then with ``braking`` the stop point."""

    def __init__(self, dt_s: float, horizon: int, loop: VelocityLoop | None, braking: Braking | None) -> None:
        self.dt_s, self.horizon, self.loop, self.braking = dt_s, horizon, loop, braking

    def points(self, state: Array, u: Array, x: Array, loop: bool = True) -> Array:
        """Relative positions (S, n, d) the drones reach with the inputs ``u`` (H, n, d): the single
        integrator's ``x``, plus the loop's offsets (not with ``loop`` False); with braking, then
        the stop point (with the loop, where it comes to rest)."""
        with_loop = loop and self.loop is not None
        y = x + self.loop.offsets(state, u)[1:] if with_loop else x  # type: ignore[union-attr]
        if self.braking is None:
            return y
        stop = self.braking.stop(x[-1], u[-1])
        if with_loop:
            stop = self.loop.dc_gain * stop + self.loop.at_rest(state)  # type: ignore[union-attr]
        return np.concatenate([y, stop[None]])

    def free(self, state: Array) -> Array:
        """The loop's free response (H + 1, n, d), then with braking where it comes to rest."""
        free = self.loop.free(state)  # type: ignore[union-attr]
        if self.braking is None:
            return free
        return np.concatenate([free, self.loop.at_rest(state)[None]])  # type: ignore[union-attr]

    def guess(self, plan: Plan | None, p0: Array, state: Array) -> Array:
        """The guess (S + 1, n, d) the rows are linearised about (:func:`mpcform.mpc.plan.guess`);
        with a loop, where the previous plan shifted takes the drones from ``p0`` (it meets its own
        rows, as the single integrator's guess does)."""
        if self.loop is None:
            return guess(plan, p0, self.horizon, self.braking)
        u = np.zeros((self.horizon,) + p0.shape)
        if plan is not None:
            u = plan.shifted_inputs() if self.braking is None else self.braking.shifted(plan.inputs_mps)
        return np.concatenate([p0[None], p0 + self.points(state, u, self.dt_s * np.cumsum(u, axis=0))])

    def on_forced(self, rows: SeparationRows, state: Array, ends: Array) -> SeparationRows:
        """With a loop, the QP's rows from ``rows`` on the true positions (at position steps
        ``ends``): the QP's rows carry the forced response, so the free one moves into their bounds
        (not in the hard no-approach rows: a drone cannot undo the velocity it has)."""
        if self.loop is None:
            return rows
        free = self.free(state)[ends].transpose(1, 0, 2)  # (n, R, d)
        shift_p = np.einsum("prd,prd->pr", rows.pair_coeffs, free[rows.pairs[:, 0]] - free[rows.pairs[:, 1]])
        shift_s = np.einsum("srd,srd->sr", rows.single_coeffs, free[rows.singles])
        shift_p[rows.pair_hard, 0] = 0.0
        shift_s[rows.single_hard, 0] = 0.0
        return replace(rows, pair_lower=rows.pair_lower - shift_p, single_lower=rows.single_lower - shift_s)
