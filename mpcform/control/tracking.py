"""The seed's two closed-form controllers: eq. 4 with eq. 7 saturation, and eq. 14 tracking."""

from __future__ import annotations

from mpcform._validate import Array, positive
from mpcform.control.base import FEEDFORWARDS, Controller, ControlStep, StepInfo, feedforward_targets
from mpcform.control.laws import check_gain_dt, count_saturated, saturate, tracking_command
from mpcform.errors import ValidationError
from mpcform.reference.base import Reference


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
        """Eq. 4: ``u = k (p* - p)``, saturated at v_max (eq. 7) when it is set."""
        p = self._check_positions(positions_m)
        target, _ = self.reference.targets(t_s)
        raw = self.gain_per_s * (target[0] - p)
        u = saturate(raw, self.v_max_mps)
        return ControlStep(u, StepInfo("law", saturated=count_saturated(raw, u)))


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
        """Eq. 14: ``u = ff + k (p* - p)``, saturated at v_max (eq. 7) when it is set."""
        p = self._check_positions(positions_m)
        target, ff = feedforward_targets(self.reference, t_s, self.dt_s, 1, self.feedforward)
        raw = tracking_command(p, target[0], ff[0], self.gain_per_s)
        u = saturate(raw, self.v_max_mps)
        return ControlStep(u, StepInfo("law", saturated=count_saturated(raw, u)))
