"""One stateful interface for every controller, and the feedforward targets they share.

A controller is reset with the initial time and positions, then called once per step with the
measured positions; it returns the command held over the next ``dt`` and per-step information.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, finite_array
from mpcform.reference.base import Reference

FEEDFORWARDS = ("jacobian", "secant")
"""Eq. 14 feedforward: ``J xi_dot_d`` (jacobian) or the secant ``(p*(t + dt) - p*(t)) / dt``."""


@dataclass(frozen=True)
class StepInfo:
    """What one control step did: ``mode`` ``law`` (closed form), ``fast_path`` (eq. 14 rollout
    met every QP row), ``qp`` (solved) or ``fallback`` (solver failed; certified safe command),
    ``saturated`` commands scaled into the speed limit, and the solver's ``status``. The planner
    reports more in its own record (:class:`mpcform.mpc.step_info.MPCStepInfo`)."""

    mode: str
    saturated: int = 0
    status: str = "ok"


@dataclass(frozen=True)
class ControlStep:
    """What a controller returns for one step: the command and what the step did."""

    command_mps: Array  # (n, d), held over [t, t + dt)
    info: StepInfo


class Controller(ABC):
    """Reset once, then :meth:`step` once per period ``dt``."""

    name: str
    reference: Reference
    dt_s: float

    def reset(self, t_s: float, positions_m: Array) -> None:  # noqa: B027 - stateless default
        """Start a run at ``t_s`` from ``positions_m`` (n, d)."""

    @property
    def scale_estimates(self) -> Array | None:
        """Each drone's own scale estimate ``s_hat_i`` (n,) now, for controllers that keep one
        (consensus, seed eq. 20); None for the others (the simulation records it when present)."""
        return None

    @abstractmethod
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """The command for ``[t_s, t_s + dt)`` given the measured positions (n, d)."""

    def lose(self, drones: Array, positions_m: Array) -> Controller:
        """The controller that stops planning for ``drones`` (lost: flipped or on the floor), the
        drones at ``positions_m`` (n, d) now: the planner's (:mod:`mpcform.mpc.safety.survivors`); this
        one itself for the others, which keep commanding every drone."""
        return self

    @property
    def lost_drones(self) -> Array:
        """The drones this controller no longer plans for (sorted)."""
        return np.zeros(0, dtype=int)

    def _check_positions(self, positions_m: Array) -> Array:
        tpl = self.reference.template
        return finite_array("positions", positions_m, (tpl.n, tpl.dim))


def feedforward_targets(
    reference: Reference, t_s: float, dt_s: float, steps: int, feedforward: str
) -> tuple[Array, Array]:
    """Targets ``p*`` at ``t + j dt`` (j = 0..steps) and feedforwards for j = 0..steps-1.

    Returns ``(targets (steps + 1, n, d), feedforward (steps, n, d))``.
    """
    pos, vel = reference.targets(t_s + dt_s * np.arange(steps + 1))
    if feedforward == "secant":
        return pos, np.diff(pos, axis=0) / dt_s
    return pos, vel[:-1]
