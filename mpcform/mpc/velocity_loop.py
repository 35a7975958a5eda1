r"""The planner's model of a drone's velocity loop: where a lagging drone really goes.

The planner's single integrator predicts ``p0 + x_e`` with ``x_e = dt sum_{j<e} u_j``. A drone
whose velocity loop is linear, per axis ``xi' = A xi + B u``, ``v = c^T xi`` (first-order lag:
``xi = v``, ``A = -1/tau``, ``B = 1/tau``; second order: ``xi = (v, v')``), flown with each
command held over its interval (the quadrotor: its hover linearisation), is instead at

.. math::
    p_e = p_0 + x_e + F_e \xi_0 + \sum_{j<e} G_{e,j} u_j        \qquad \text{(per axis)},

exactly (one matrix exponential of the system ``(p, xi)`` per axis group). ``F_e xi_0`` is the
*free* response (the velocity the drone already has, e.g. the lag's overshoot ``tau (1 - a^e)
v_0``) and ``G`` the *forced* one (a lag lags its commands: ``G_{e,j} = -tau (1 - a) a^{e-1-j}``,
``a = e^{-dt/tau}``). The planner writes its separation, obstacle and fence rows on these true
positions: rows linear in ``u``, exact for the plant without wind, so a braking plan no longer
overshoots into a partner.

The loop state ``xi_0`` is not measured: :meth:`VelocityLoop.advance` runs the model on the
commands sent (a drone at rest at the start), exact for a linear plant without wind. Wind (and a
quadrotor's departure from its hover linearisation) moves the drone by ``r_k`` more than the model
predicted over the last interval. The state's last component is a velocity offset ``delta``
[m/s], set by :meth:`VelocityLoop.observe` to the last interval's mean, ``delta += r_k / dt`` (a
deadbeat disturbance estimate), and held over the whole plan (``F_e`` carries ``e dt`` for it):
the disturbance model of offset-free MPC (Pannocchia and Rawlings 2003; Maeder, Borrelli and
Morari 2009), the velocity over ground ``v = u + delta``.

**The command with an estimate.** The cost tracks the reference on the velocity over ground and
the displacement with the offset, ``sum_j ||u_j + delta - ff_j - k (p*_j - p0 - x_j - j dt
delta)||^2`` (:func:`mpcform.mpc.pipeline.cost_shift`; ``delta`` here the low-pass estimate
``delta_c`` below), so when no row is active the command is

.. math::
    u = J \dot\xi_d + k (p^* - p) - \delta \qquad \text{(eq. 14 less the offset)},

and a constant disturbance leaves no steady-state error (a lag in a steady wind ``w`` settles at
``delta = c tau w``; without the cancellation it stayed ``c tau |w| / k`` off). With no offset
estimated (the ideal plant, ``plant_model`` off, or an exact zero) the command is eq. 14, bitwise.
The velocity set and the acceleration rows stay on the command sent ``u``, and the certifier
checks that command; the braking tail brakes the velocity over ground, its commands towards
``-delta`` (:func:`mpcform.mpc.constraints.tail.with_offset`), so a drone holding in wind
(``u = -delta``) rests where it is.

**Two estimates.** The rows take the deadbeat estimate ``delta`` over the whole plan: the first
interval needs it (the margin covers what it misses, :func:`mpcform.sim.margin.modelled_margin`),
and carried over the plan a miss ``r`` moves the shifted plan's position at step ``e`` by ``(e +
1) r`` at worst; the rows grow by one worst miss per interval (:func:`mpcform.sim.margin.wind_growth`),
and :class:`mpcform.mpc.safety.premise.GrowthPremise` reports each step the move exceeds it (a
steady wind's first few: the plan no longer moves by the wind's mean). A low-pass estimate there
would move the plan by its lag behind the deadbeat one instead, up to the gusts' whole span. The
command cancels a low-pass of it, ``delta_c += (1 - e^{-dt / T}) (delta - delta_c)`` with ``T =``
:data:`CANCEL_TIME_S` (:meth:`VelocityLoop.cancelled`): the same in a steady wind, but without
the gusts' chatter (and position noise ``sigma``, which enters ``delta`` as ``sqrt(2) sigma /
dt``). The cost's displacement then carries ``delta_c``, the rows ``delta``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.linalg import expm

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.world.loop_groups import LoopGroup

CANCEL_TIME_S = 0.3
"""Time constant [s] of the low-pass observer of the offset the commands cancel (module docstring).
Position noise enters the deadbeat estimate divided by ``dt``: a 10-drone ring on a lag of 0.3 s in
a steady 1.7 m/s wind with 5 mm of measurement noise (dt 0.1) changed its commands by 0.138 m/s
per step cancelling it whole, 0.038 through this observer (0.009 without cancelling, 0.235 m off
its goal), and ended 2.6 mm off on average instead of 6.6 mm; a steady wind's offset it takes out
within about a second."""


@dataclass(frozen=True, eq=False)
class VelocityLoop:
    """Per-axis linear velocity loop discretised at ``dt_s`` over ``horizon`` intervals.

    ``free_m`` (H + 1, d, s): ``F_e``; ``forced`` (H + 1, H, d): ``G_{e,j}`` (zero for ``j >= e``);
    ``step_state`` (d, s, s) and ``step_input`` (d, s): one interval of the loop state, whose last
    component is the velocity offset ``delta``, persistent over the plan (module docstring);
    ``speed_gain``: the L1 norm of the velocity's impulse response (the total variation of its step
    response), so ``|v| <= speed_gain v_max`` for commands within ``v_max`` (1 for a lag);
    ``rest_m`` (d, s): ``F_rest``, the free response once the loop has come to rest (the lag's
    ``tau v_0``; the offset's column, 0 here, is the braking tail's:
    :func:`mpcform.mpc.constraints.tail.with_offset`); ``dc_gain`` (d,): how far the loop carries a
    drone per metre of commanded travel once at rest (1 for every loop here, whose velocity
    settles on the command), so a plan braking to rest ends at ``dc_gain x_stop + F_rest xi_0``
    (:mod:`mpcform.mpc.constraints.braking`); ``lag_s``: how far behind its commands the loop comes to rest
    from a steady command, per m/s (``tau`` for a lag).
    """

    dt_s: float
    free_m: Array
    forced: Array
    step_state: Array
    step_input: Array
    speed_gain: float
    rest_m: Array
    dc_gain: Array
    lag_s: float

    @classmethod
    def from_groups(cls, groups: list[LoopGroup], dim: int, dt_s: float, horizon: int) -> VelocityLoop:
        """The loop of per-axis groups ``(A, B, c, axes)`` (axes beyond ``dim`` ignored)."""
        s = max(a.shape[0] for a, _, _, _ in groups) + 1  # the loops' states, then delta
        free, forced = np.zeros((horizon + 1, dim, s)), np.zeros((horizon + 1, horizon, dim))
        step_state, step_input = np.zeros((dim, s, s)), np.zeros((dim, s))
        covered, gain = np.zeros(dim, dtype=bool), 1.0
        rest, dc, lag = np.zeros((dim, s)), np.ones(dim), 0.0
        for a, b, c, axes in groups:
            k = a.shape[0]
            m = np.zeros((k + 2, k + 2))  # (p, xi, u): p' = c^T xi, xi' = A xi + B u, u' = 0
            m[0, 1 : k + 1], m[1 : k + 1, 1 : k + 1], m[1 : k + 1, k + 1] = c, a, b
            ex = expm(m * dt_s)
            phi, gam = ex[: k + 1, : k + 1], ex[: k + 1, k + 1]
            powers = [np.eye(k + 1)]
            for _ in range(horizon):
                powers.append(phi @ powers[-1])
            f_e = np.array([pw[0, 1:] for pw in powers])  # (H + 1, k): e_p^T phi^e on xi
            g_m = np.array([pw[0] @ gam for pw in powers[:horizon]]) - dt_s  # input m steps back
            for ax in (x for x in axes if x < dim):
                covered[ax] = True
                free[:, ax, :k] = f_e
                for e in range(1, horizon + 1):
                    forced[e, :e, ax] = g_m[e - 1 :: -1][:e]
                step_state[ax, :k, :k], step_input[ax, :k] = phi[1:, 1:], gam[1:]
                rest[ax, :k] = -np.linalg.solve(a.T, c)  # c^T (-A)^-1: the integral of c^T e^{At}
                dc[ax] = rest[ax, :k] @ b
                lag = max(lag, abs(float(rest[ax, :k] @ np.linalg.solve(a, -b))))  # from the steady state
            gain = max(gain, _step_variation(a, b, c))
        free[:, :, -1] = dt_s * np.arange(horizon + 1)[:, None]  # delta persists: e dt delta at step e
        step_state[:, -1, -1] = 1.0
        if not covered.all():
            axes_given = np.flatnonzero(covered).tolist()
            raise ValidationError("plant", f"the loop covers axes {axes_given}, expected 0..{dim - 1}")
        return cls(dt_s, free, forced, step_state, step_input, gain, rest, dc, lag)

    @property
    def reach_factor(self) -> float:
        """How much farther than the single integrator (``e v_max dt``) the forced response can
        carry a drone in ``e`` steps, at most (1 for a lag; above 1 for a loop that overshoots)."""
        h = self.forced.shape[1]
        steps = self.forced[1:] + self.dt_s  # (H, H, d): displacement at step e per unit input j < e
        mask = np.tril(np.ones((h, h), dtype=bool))[:, :, None]
        per = np.abs(np.where(mask, steps, 0.0)).sum(axis=1) / (np.arange(1, h + 1)[:, None] * self.dt_s)
        return max(1.0, float(per.max()))

    @cached_property
    def steady_state(self) -> Array:
        """The loop state (d, s - 1) per m/s of a command held until the loop settles (the lag's
        ``xi = 1``), without the offset: ``(I - Phi)^-1 Gamma`` per axis."""
        s = self.step_state.shape[1] - 1
        eye = np.eye(s)
        return np.array(
            [
                np.linalg.solve(eye - phi[:s, :s], gam[:s])
                for phi, gam in zip(self.step_state, self.step_input, strict=True)
            ]
        )

    def rest(self, n: int) -> Array:
        """The loop state (n, d, s) of drones at rest."""
        return np.zeros((n,) + self.step_input.shape)

    def advance(self, state: Array, u: Array) -> Array:
        """The loop state (n, d, s) one interval after ``state`` with the commands ``u`` (n, d)."""
        return np.einsum("dst,ndt->nds", self.step_state, state) + u[..., None] * self.step_input

    @property
    def cancel_gain(self) -> float:
        """The observer's gain [-] per interval of the offset the commands cancel
        (:data:`CANCEL_TIME_S`): ``1 - e^{-dt / T}``."""
        return float(-np.expm1(-self.dt_s / CANCEL_TIME_S))

    def cancelled(self, offset_mps: Array | None, state: Array) -> Array:
        """The offset (n, d) [m/s] the commands cancel after observing ``state`` (n, d, s): the last
        one ``offset_mps`` moved by :attr:`cancel_gain` towards the state's deadbeat estimate (None
        before the first observation: from 0)."""
        delta = state[..., -1]
        if offset_mps is None:
            return self.cancel_gain * delta
        return offset_mps + self.cancel_gain * (delta - offset_mps)

    def observe(self, state: Array, residual_m: Array) -> Array:
        """The state (n, d, s) with its velocity offset moved by ``residual_m / dt`` (n, d): where
        the drones are minus where the model took them over the last interval."""
        out = state.copy()
        out[..., -1] += residual_m / self.dt_s
        return out

    def free(self, state: Array) -> Array:
        """The free response ``F_e xi_0`` (H + 1, n, d) [m] of drones in loop ``state`` (n, d, s)."""
        return np.einsum("eds,nds->end", self.free_m, state)

    def first(self, state: Array, u0: Array) -> Array:
        """The offset (n, d) [m] at the end of the first interval for the commands ``u0`` (n, d)."""
        return np.einsum("ds,nds->nd", self.free_m[1], state) + self.forced[1, 0] * u0

    def offsets(self, state: Array, u: Array) -> Array:
        """``p_e - p0 - x_e`` (H + 1, n, d) [m] for the inputs ``u`` (H, n, d) from ``state``."""
        return self.free(state) + self.forced_response(u)

    def forced_response(self, u: Array) -> Array:
        """``sum_{j<e} G_{e,j} u_j`` (H + 1, n, d) [m] of the inputs ``u`` (H, n, d)."""
        return np.einsum("ejd,jnd->end", self.forced, u)


def _step_variation(a: Array, b: Array, c: Array, samples: int = 4000) -> float:
    """Total variation of the velocity's unit step response ``c^T xi`` from rest (until it settles:
    20 of the slowest time constants), sampled finely."""
    slowest = 1.0 / min(abs(np.linalg.eigvals(a).real))
    phi = expm(np.block([[a, b[:, None]], [np.zeros((1, a.shape[0] + 1))]]) * (20.0 * slowest / samples))
    z, g = np.zeros(a.shape[0] + 1), np.empty(samples + 1)
    z[-1] = 1.0
    for i in range(samples + 1):
        g[i] = c @ z[:-1]
        z = phi @ z
    return float(np.abs(np.diff(g)).sum())
