"""Where a plan takes the drones: the single integrator, the velocity loop's offsets
(:mod:`mpcform.mpc.velocity_loop`) and the braking tail's points (:mod:`mpcform.mpc.constraints.tail`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.constraints.tail import Tail
from mpcform.mpc.plan import Plan, guess
from mpcform.mpc.velocity_loop import VelocityLoop


def rest_command(state: Array) -> Array:
    """The command (n, d) [m/s] drones in loop ``state`` (n, d, s) rest at: ``-delta``, the velocity
    offset's estimate (:mod:`mpcform.mpc.velocity_loop`)."""
    return -state[..., -1]


class Prediction:
    """The positions the separation rows and tests are written on, for drones in loop ``state``
    (n, d, s) (no states without a ``loop``): steps 1..H, then with ``braking`` the ``tail``'s points."""

    def __init__(
        self, dt_s: float, horizon: int, loop: VelocityLoop | None, braking: Braking | None, tail: Tail | None
    ) -> None:
        self.dt_s, self.horizon, self.loop, self.braking, self.tail = dt_s, horizon, loop, braking, tail
        self._offset_reach_s = 0.0  # how far [m] 1 m/s of velocity offset carries a drone, at most
        if loop is not None:
            self._offset_reach_s = float(np.abs(loop.free_m[..., -1]).max())
            if tail is not None and tail.free is not None:
                self._offset_reach_s = max(self._offset_reach_s, float(np.abs(tail.free[..., -1]).max()))

    @property
    def speed_gain(self) -> float:
        """How much faster than its commands the loop may fly a drone (1 without a loop)."""
        return 1.0 if self.loop is None else self.loop.speed_gain

    @property
    def tail_s(self) -> float:
        """How far [s] past ``x_H`` the braking tail's points lie (0 without braking)."""
        if self.braking is None or self.tail is None:
            return 0.0
        lag = 0.0 if self.loop is None else self.loop.lag_s
        return max(self.braking.kappa_s * self.speed_gain, self.tail.reach_s) + lag

    def drift_m(self, state: Array) -> float:
        """How far [m] the velocity offset of drones in loop ``state`` (n, d, s) carries one at most
        over the plan and its tail (0 without a loop)."""
        if self.loop is None or not state.size:
            return 0.0
        speed = float(np.sqrt(np.einsum("nd,nd->n", state[..., -1], state[..., -1]).max()))
        return self._offset_reach_s * speed

    def points(self, state: Array, u: Array, x: Array) -> Array:
        """Relative positions (S, n, d) the drones reach with the inputs ``u`` (H, n, d): the single
        integrator's ``x``, plus the loop's offsets; with braking, then the tail's points, the
        stop point last (with the loop, where it comes to rest; :mod:`mpcform.mpc.constraints.tail`)."""
        y = x if self.loop is None else x + self.loop.offsets(state, u)[1:]
        if self.tail is None:
            return y
        return np.concatenate([y, self.tail.points(x[-1], u, state)])

    def free(self, state: Array) -> Array:
        """The loop's free response (H + 1, n, d), then with braking at the tail's points."""
        free = self.loop.free(state)  # type: ignore[union-attr]
        if self.tail is None:
            return free
        return np.concatenate([free, self.tail.free_response(state)])

    def guess(self, plan: Plan | None, p0: Array, state: Array) -> Array:
        """The guess (S + 1, n, d) the rows are linearised about (:func:`mpcform.mpc.plan.guess`);
        with a loop, where the previous plan shifted takes the drones from ``p0`` (it meets its own
        rows, as the single integrator's guess does)."""
        if self.loop is None:
            return guess(plan, p0, self.horizon, self.braking)
        u = np.zeros((self.horizon,) + p0.shape)
        if plan is not None:
            u = plan.shifted_inputs()
            if self.braking is not None:  # braking towards the command the drones rest at in wind
                u = self.braking.shifted(plan.inputs_mps, rest_command(state))
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
