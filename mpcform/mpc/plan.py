"""The plan and what the next step takes from it: the eq. 14 rollout, the guess, the warm start.

Positions ``x`` are relative to the step's start ``p0``; a :class:`Plan` keeps absolute ones.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.braking import Braking


@dataclass(frozen=True)
class Plan:
    """Predicted inputs (H, n, d) [m/s] and positions (H + 1, n, d) [m], row 0 the start."""

    inputs_mps: Array
    positions_m: Array

    @classmethod
    def from_relative(cls, p0: Array, u: Array, x: Array) -> Plan:
        """The plan of inputs ``u`` and positions ``x`` (H, n, d) relative to the start ``p0`` (n, d)."""
        return cls(u, np.concatenate([p0[None], p0 + x]))

    def shifted_inputs(self, a_step_mps: float | None = None) -> Array:
        """Inputs (H, n, d) shifted one step, ending in a hold; with ``a_step_mps`` (a_max dt) the last
        step slows down by at most that much per component instead.

        The hold keeps the shifted plan's positions collision-free (the last position repeats),
        but it can break the acceleration rows at the last step (``|u_{H-1}| > a_max dt``): without
        a terminal rest constraint, the shifted plan is not always a zero-slack candidate for the
        next QP when ``a_max`` is set; the guess (:func:`guess`) keeps the hold, the fallback's plan
        slows down within ``a_max``."""
        last = np.zeros((1,) + self.inputs_mps.shape[1:])
        if a_step_mps is not None:
            last[0] = self.inputs_mps[-1] - np.clip(self.inputs_mps[-1], -a_step_mps, a_step_mps)
        return np.concatenate([self.inputs_mps[1:], last])


@dataclass(frozen=True, eq=False)
class Nominal:
    """One step's eq. 14 rollout: the targets (H + 1, n, d) and the cost's ``c`` (H, n, d) [m/s],
    its inputs ``u`` and relative positions ``x`` (H, n, d), where it takes the drones ``x_true``
    (S, n, d) (with a loop and the braking tail), as a ``plan``, its ``true_path`` (S + 1, n, d)
    from the start, the ``guess`` (S + 1, n, d) the rows are linearised about, the drones it takes
    off a limit row ``off_limits`` (n,), each drone's share of the rows' growth ``growing``
    (n,) (None: no growth), and with an estimated velocity offset what ``c`` cancels of it
    ``cancel`` (H, n, d) (:func:`mpcform.mpc.pipeline.cost_shift`; None: nothing)."""

    targets: Array
    c: Array
    u: Array
    x: Array
    x_true: Array
    plan: Plan
    true_path: Array
    guess: Array
    off_limits: Array
    growing: Array | None
    cancel: Array | None = None


def rollout(c: Array, k: float, dt: float) -> tuple[Array, Array]:
    """Eq. 14 over the horizon in relative coordinates: ``u_j = c_j - k x_j``, ``x_{j+1} = x_j + dt u_j``,
    in closed form ``x_{j+1} = sum_{i <= j} dt (1 - k dt)^(j - i) c_i`` (one product; ``u_0 = c_0``)."""
    h = c.shape[0]
    x = (_decay(h, k, dt) @ c.reshape(h, -1)).reshape(c.shape)
    u = c.copy()
    u[1:] -= k * x[:-1]
    return u, x


def braking_error(error_m: Array, k: float, a_max_mps2: float | None, v_max_mps: float | None) -> Array:
    """The errors ``p*_j - p0`` (H, n, d) of eq. 14's cost when a drone must still brake: where
    eq. 14's feedback speed ``k |e_0|`` and ``v_max`` both exceed ``sqrt(a_max |e_0|)`` (the speed
    from which braking at half ``a_max`` stops at the target, the other half left to the plant's
    lag and the discrete steps), every error of the drone is moved by the one shift that shortens
    ``e_0`` to that speed's ``|e_0| = sqrt(a_max |e_0|) / k``: the drone approaches its target (or a
    moving target's path) on a braking profile instead of overshooting where it cannot stop, which
    a short horizon does not see. Within ``a_max / k^2`` of its target, or without ``a_max``, the
    errors are unchanged, so eq. 14 holds there exactly."""
    if a_max_mps2 is None:
        return error_m
    e0 = error_m[0]
    dist = np.sqrt(np.einsum("nd,nd->n", e0, e0))
    brake = np.sqrt(a_max_mps2 * dist)
    over = brake < np.minimum(k * dist, np.inf if v_max_mps is None else v_max_mps)
    if not over.any():
        return error_m
    shift = np.zeros_like(e0)
    shift[over] = e0[over] * (brake[over] / (k * dist[over]) - 1.0)[:, None]
    return error_m + shift[None]


@lru_cache(maxsize=16)
def _decay(h: int, k: float, dt: float) -> Array:
    """The rollout's matrix (H, H): ``dt (1 - k dt)^(j - i)`` for ``i <= j``, else 0 (read-only)."""
    j = np.arange(h)
    out = np.tril(dt * (1.0 - k * dt) ** np.maximum(j[:, None] - j[None, :], 0))
    out.flags.writeable = False
    return out


def guess(plan: Plan | None, p0: Array, horizon: int, braking: Braking | None = None) -> Array:
    """Absolute guess positions (H + 1, n, d) about which the separation rows are linearised: the
    previous plan shifted one step, ending in a hold (at the first step every drone holding).
    With ``braking`` (:mod:`mpcform.mpc.constraints.braking`) the shifted plan brakes at its last step and the
    guess ends in its stop point (H + 2 positions), the previous plan's own."""
    steps = horizon + 1 + (braking is not None)
    if plan is None:
        return np.broadcast_to(p0, (steps,) + p0.shape)
    prev = plan.positions_m
    if braking is None:
        return np.concatenate([p0[None], prev[2:], prev[-1:]])
    u_last = plan.inputs_mps[-1]
    last = prev[-1] + braking.dt_s * braking.rho * u_last
    return np.concatenate([p0[None], prev[2:], last[None], braking.stop(prev[-1], u_last)[None]])


def warm_start(
    plan: Plan | None,
    p0: Array,
    u_nom: Array,
    x_nom: Array,
    braking: Braking | None = None,
    rest_mps: Array | None = None,
) -> Array:
    """Primal warm start (2, H, n, d): inputs and relative positions of the previous plan shifted
    one step (or of the rollout ``u_nom``, ``x_nom`` at the first step); with ``braking`` its last
    step brakes (towards ``rest_mps``, :meth:`mpcform.mpc.constraints.braking.Braking.shifted`)."""
    if plan is None:
        return np.stack([u_nom, x_nom])
    if braking is None:
        x = np.concatenate([plan.positions_m[2:], plan.positions_m[-1:]]) - p0
        return np.stack([plan.shifted_inputs(), x])
    u = braking.shifted(plan.inputs_mps, rest_mps)
    x = np.concatenate([plan.positions_m[2:], plan.positions_m[-1:] + braking.dt_s * u[-1:]]) - p0
    return np.stack([u, x])


def merge(drones: Array, z: Array, u_nom: Array, x_nom: Array) -> tuple[Array, Array]:
    """Inputs and relative positions (H, n, d): the QP solution ``z``'s for ``drones`` (its first
    variables: the inputs, then the positions, each (H, len(drones), d)), the rollout's for the
    others."""
    horizon, m, dim = u_nom.shape[0], drones.shape[0], u_nom.shape[2]
    nud = horizon * m * dim
    u, x = u_nom.copy(), x_nom.copy()
    u[:, drones] = z[:nud].reshape(horizon, m, dim)
    x[:, drones] = z[nud : 2 * nud].reshape(horizon, m, dim)
    return u, x
