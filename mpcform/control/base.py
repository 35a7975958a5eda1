"""One stateful interface for every controller, and the seed's two closed-form controllers.

A controller is reset with the initial time and positions, then called once per step with the
measured positions; it returns the command held over the next ``dt`` and per-step information.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, finite_array, positive
from mpcform.control.laws import check_gain_dt, saturate, tracking_command
from mpcform.errors import ValidationError
from mpcform.reference.base import Reference

FEEDFORWARDS = ("jacobian", "secant")


@dataclass(frozen=True)
class StepInfo:
    """What one control step did.

    ``mode``: ``law`` (closed form), ``fast_path`` (eq. 14 rollout met every QP row), ``qp``
    (solved), or ``fallback`` (solver failed; certified safe command). ``slack_pairs`` lists the
    drone pairs (or ``(drone, -1 - obstacle)``) whose separation rows needed slack; ``qp_drones``
    how many drones the QP was solved for (the others' groups took the fast path).
    """

    mode: str
    saturated: int = 0
    status: str = "ok"
    iterations: int = 0
    solve_time_s: float = 0.0
    active_rows: int = 0
    max_slack_m: float = 0.0
    slack_pairs: tuple[tuple[int, int], ...] = ()
    qp_drones: int = 0


@dataclass(frozen=True)
class ControlStep:
    command_mps: Array  # (n, d), held over [t, t + dt)
    info: StepInfo


class Controller(ABC):
    """Reset once, then :meth:`step` once per period ``dt``."""

    name: str
    reference: Reference
    dt_s: float

    def reset(self, t_s: float, positions_m: Array) -> None:  # noqa: B027 - stateless default
        """Start a run at ``t_s`` from ``positions_m`` (n, d)."""

    @abstractmethod
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """The command for ``[t_s, t_s + dt)`` given the measured positions (n, d)."""

    def _check_positions(self, positions_m: Array) -> Array:
        tpl = self.reference.template
        return finite_array("positions", positions_m, (tpl.n, tpl.dim))


class ProportionalController(Controller):
    """Eq. 4 with eq. 7 saturation: each drone flies to its target ``p*_i(t)`` without feedforward."""

    name = "proportional"

    def __init__(
        self, reference: Reference, gain_per_s: float, dt_s: float, v_max_mps: float | None = None
    ) -> None:
        check_gain_dt(gain_per_s, dt_s)
        self.reference, self.gain_per_s, self.dt_s = reference, gain_per_s, dt_s
        self.v_max_mps = None if v_max_mps is None else positive("limits.v_max", v_max_mps)

    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        p = self._check_positions(positions_m)
        target, _ = self.reference.targets(t_s)
        raw = self.gain_per_s * (target[0] - p)
        u = saturate(raw, self.v_max_mps)
        return ControlStep(u, StepInfo("law", saturated=_count_changed(raw, u)))


class TrackingController(Controller):
    """Eq. 14: feedforward plus ``k (p* - p)``, optionally saturated exactly (eq. 7).

    ``feedforward="jacobian"`` uses ``J xi_dot_d`` (exact in continuous time, O(dt) error in
    discrete time); ``"secant"`` uses ``(p*(t + dt) - p*(t)) / dt``, for which the discrete
    error decays exactly as ``(1 - k dt)^j``.
    """

    name = "tracking"

    def __init__(
        self,
        reference: Reference,
        gain_per_s: float,
        dt_s: float,
        v_max_mps: float | None = None,
        feedforward: str = "jacobian",
    ) -> None:
        check_gain_dt(gain_per_s, dt_s)
        if feedforward not in FEEDFORWARDS:
            raise ValidationError(
                "controller.feedforward", f"expected one of {FEEDFORWARDS}, got {feedforward!r}"
            )
        self.reference, self.gain_per_s, self.dt_s = reference, gain_per_s, dt_s
        self.v_max_mps = None if v_max_mps is None else positive("limits.v_max", v_max_mps)
        self.feedforward = feedforward

    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        p = self._check_positions(positions_m)
        target, ff = feedforward_targets(self.reference, t_s, self.dt_s, 1, self.feedforward)
        raw = tracking_command(p, target[0], ff[0], self.gain_per_s)
        u = saturate(raw, self.v_max_mps)
        return ControlStep(u, StepInfo("law", saturated=_count_changed(raw, u)))


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


def _count_changed(raw: Array, u: Array) -> int:
    return int(np.any(raw != u, axis=-1).sum())
