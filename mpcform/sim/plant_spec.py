"""What a scenario's ``[plant]`` table declares, and the one factory that builds the plant from it.

A :class:`PlantSpec` holds the plant's kind and parameters, the wind and the measurement noise;
:meth:`PlantSpec.build` makes the vectorised plant for n drones in d dimensions (see
:mod:`mpcform.sim.plants` and :mod:`mpcform.sim.quadrotor`), and :meth:`PlantSpec.margin` the
robust margin the planner tightens its rows by (:mod:`mpcform.sim.margin`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mpcform._validate import positive
from mpcform.errors import ValidationError
from mpcform.sim.plants import KINDS, SAMPLES_PER_STEP, IdealPlant, Plant, lag_plant, second_order_plant
from mpcform.sim.wind import Wind
from mpcform.world.loop import LoopGroup

DEFAULT_TIME_CONSTANT_S = 0.1
DEFAULT_DAMPING = 0.7
DEFAULT_NATURAL_FREQUENCY_RAD_S = 6.0
DEFAULT_RATE_HZ = 500.0
DEFAULT_ALTITUDE_M = 1.0


@dataclass(frozen=True)
class Robustness:
    """What the planner assumes of a plant: the robust margin per drone ``margin_m`` [m] its rows
    are tightened by (pairs by twice it), the command-change bound ``a_max_mps2`` the margin holds
    for (the scenario's ``limits.a_max``, else the plant's default), and the speed below which the
    quadrotor's margin is valid (inf for the linear plants)."""

    margin_m: float
    a_max_mps2: float | None
    valid_speed_mps: float = float("inf")
    loop: tuple[LoopGroup, ...] = ()
    """The plant's velocity loops ``(A, B, c, axes)`` per axis group, which the planner can model
    (:mod:`mpcform.mpc.loop`; the quadrotor's hover linearisation); empty for the ideal plant."""


@dataclass(frozen=True, eq=False)
class PlantSpec:
    """A plant as declared: ``kind`` and its parameters (the others are ignored), wind, noise.

    ``margin_m``: the robust margin per drone [m] the planner tightens its rows by; None computes
    it from the plant (:func:`mpcform.sim.margin.plant_margin`), a number overrides it.
    """

    kind: str = "ideal"
    time_constant_s: float = DEFAULT_TIME_CONSTANT_S
    damping: float = DEFAULT_DAMPING
    natural_frequency_rad_s: float = DEFAULT_NATURAL_FREQUENCY_RAD_S
    damping_z: float | None = None
    natural_frequency_z_rad_s: float | None = None
    platform: str = "cf2x_L250"
    model: str = "so_rpy_rotor_drag"
    rate_hz: float = DEFAULT_RATE_HZ
    altitude_m: float = DEFAULT_ALTITUDE_M
    wind: Wind | None = None
    measurement_noise_m: float = 0.0
    margin_m: float | None = None
    samples_per_step: int = SAMPLES_PER_STEP

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValidationError("plant.kind", f"expected one of {', '.join(KINDS)}, got {self.kind!r}")
        positive("plant.time_constant", self.time_constant_s)
        positive("plant.damping", self.damping)
        positive("plant.natural_frequency", self.natural_frequency_rad_s)
        for name in ("damping_z", "natural_frequency_z_rad_s"):
            if getattr(self, name) is not None:
                positive(f"plant.{name.removesuffix('_rad_s')}", getattr(self, name))
        positive("plant.rate", self.rate_hz)
        if not math.isfinite(self.altitude_m):
            raise ValidationError("plant.altitude", f"expected a finite height [m], got {self.altitude_m!r}")
        positive("plant.measurement_noise", self.measurement_noise_m, allow_zero=True)
        if self.margin_m is not None:
            positive("plant.margin", self.margin_m, allow_zero=True)
        if self.kind == "ideal" and self.wind is not None:
            raise ValidationError(
                "plant.wind",
                "the ideal plant is the planner's own model and takes no wind: choose "
                "plant.kind = lag, second_order or quadrotor",
            )

    @property
    def ideal(self) -> bool:
        """True for the exact single integrator without measurement noise (the planner's model)."""
        return self.kind == "ideal" and self.measurement_noise_m == 0.0

    def robustness(
        self, dim: int, dt_s: float, a_max_mps2: float | None, loop_modelled: bool = False
    ) -> Robustness:
        """The margin and acceleration bound the planner uses for this plant (module
        :mod:`mpcform.sim.margin`): zero for the ideal plant; otherwise ``margin_m`` if given, else
        the plant's margin over one control interval of ``dt_s`` with ``a_max_mps2`` (None: the
        plant's default); with ``loop_modelled`` (the MPC's rows model the plant's velocity loop at
        the interval ends, :mod:`mpcform.mpc.loop`) only what that model leaves out
        (:func:`mpcform.sim.margin.modelled_margin`). Measurement noise is not part of it."""
        if self.kind == "ideal":
            return Robustness(self.margin_m or 0.0, a_max_mps2)
        from mpcform.sim.margin import default_a_max, modelled_margin, plant_margin

        plant = self.build(1, dim)
        a_max = default_a_max(plant) if a_max_mps2 is None else a_max_mps2
        margin = plant_margin(plant, dt_s, a_max)
        loop = tuple((a, b, c, axes) for a, b, _, c, axes in plant.velocity_loops())
        computed = margin.norm_m
        if loop_modelled:  # the interval ends are modelled: the wind, the bend within, the remainder
            computed = float(np.linalg.norm(modelled_margin(plant, dt_s, a_max, margin)))
        chosen = computed if self.margin_m is None else self.margin_m
        return Robustness(chosen, a_max, margin.valid_speed_mps, loop)

    def build(self, n: int, dim: int, seed: int | np.random.SeedSequence = 0) -> Plant:
        """The plant for ``n`` drones in ``dim`` dimensions; ``seed`` feeds its wind and noise."""
        common: dict[str, object] = {
            "wind": self.wind,
            "noise_std_m": self.measurement_noise_m,
            "seed": seed,
            "samples_per_step": self.samples_per_step,
        }
        if self.kind == "ideal":
            return IdealPlant(n, dim, **common)
        if self.kind == "lag":
            return lag_plant(n, dim, self.time_constant_s, **common)  # type: ignore[arg-type]
        if self.kind == "second_order":
            return second_order_plant(
                n,
                dim,
                self.damping,
                self.natural_frequency_rad_s,
                zeta_z=self.damping_z,
                omega_z_rad_s=self.natural_frequency_z_rad_s,
                **common,  # type: ignore[arg-type]
            )
        from mpcform.sim.quadrotor import QuadrotorPlant, QuadrotorSpec

        spec = QuadrotorSpec(self.platform, self.model, self.rate_hz, altitude_m=self.altitude_m)
        return QuadrotorPlant(n, dim, spec, **common)
