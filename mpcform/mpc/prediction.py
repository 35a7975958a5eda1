"""Where a plan takes the drones: the single integrator, the velocity loop's offsets
(:mod:`mpcform.mpc.loop`) and the braking tail's stop point (:mod:`mpcform.mpc.braking`)."""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.braking import Braking
from mpcform.mpc.loop import VelocityLoop
from mpcform.mpc.plan import Plan, guess


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
