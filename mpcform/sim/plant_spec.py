"""What a scenario's ``[plant]`` table declares, one frozen dataclass per plant kind.

:class:`PlantSpec` is the common base: the wind, the measurement noise, the robust margin and the
plant's samples per control step. Each kind adds its own parameters with their defaults, stated
once as dataclass field defaults (the scenario key reference reads them from there):
:class:`IdealPlantSpec`, :class:`LagPlantSpec`, :class:`SecondOrderPlantSpec` and
:class:`QuadrotorPlantSpec` (whose defaults are :class:`~mpcform.sim.quadrotor.QuadrotorSpec`'s).
:data:`PLANT_SPECS` maps ``kind`` to its class. A field's scenario key is its name without the
unit (:func:`scenario_key`: ``rate_hz`` is ``plant.rate``); errors name that key.

:meth:`PlantSpec.build` makes the vectorised plant for n drones in d dimensions (see
:mod:`mpcform.sim.plants` and :mod:`mpcform.sim.quadrotor`), and :meth:`PlantSpec.robustness` the
robust margin the planner tightens its rows by (:mod:`mpcform.sim.margin`).
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from mpcform._validate import positive
from mpcform.errors import ValidationError
from mpcform.sim.crazyflow import CrazyflowPlant, check_settings
from mpcform.sim.plants import KINDS, SAMPLES_PER_STEP, IdealPlant, Plant, lag_plant, second_order_plant
from mpcform.sim.quadrotor import QuadrotorPlant, QuadrotorSpec
from mpcform.sim.wind import Wind
from mpcform.world.loop_groups import LoopGroup

UNIT_SUFFIXES = ("_rad_s", "_hz", "_s", "_m")
COMMON_FIELDS = ("wind", "measurement_noise_m", "margin_m", "margin_growth_m", "samples_per_step")
"""The fields every plant kind shares (:class:`PlantSpec`); the others are its own."""
"""The unit suffixes of field names that scenario keys leave out."""


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
    (:mod:`mpcform.mpc.velocity_loop`; the quadrotor's hover linearisation); empty for the ideal plant."""
    growth_m: float = 0.0
    """In wind: how far [m] per control interval the wind's change can move a drone off the plan
    (:func:`mpcform.sim.margin.wind_growth`); the MPC's rows grow by it along the horizon."""


def scenario_key(name: str) -> str:
    """The ``[plant]`` key of the field ``name``: the name without its unit (``rate_hz``: ``rate``)."""
    for suffix in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return name.removesuffix(suffix)
    return name


@dataclass(frozen=True, kw_only=True)
class PlantSpec(ABC):
    """What every plant kind declares: ``wind`` (None: calm), ``measurement_noise_m`` [m] (std of
    the noise on the positions the controller sees), ``margin_m`` [m] (the robust margin per drone
    the planner tightens its rows by; None computes it from the plant,
    :func:`mpcform.sim.margin.plant_margin`), ``margin_growth_m`` [m] (how much the MPC's rows grow
    per interval along the horizon; None computes it from the wind,
    :func:`mpcform.sim.margin.wind_growth`) and ``samples_per_step`` (the plant's samples per
    control step). These common fields are keyword-only (a kind's own may be positional); build a
    kind's subclass, or :func:`plant_spec` by ``kind``."""

    kind: ClassVar[str]
    wind: Wind | None = None
    measurement_noise_m: float = 0.0
    margin_m: float | None = None
    margin_growth_m: float | None = None
    samples_per_step: int = SAMPLES_PER_STEP

    def __post_init__(self) -> None:
        self._positive("measurement_noise_m", allow_zero=True)
        for name in ("margin_m", "margin_growth_m"):
            if getattr(self, name) is not None:
                self._positive(name, allow_zero=True)

    def _positive(self, name: str, *, allow_zero: bool = False) -> None:
        """Field ``name`` must be a finite number > 0 (>= 0 with ``allow_zero``); errors name its key."""
        positive(f"plant.{scenario_key(name)}", getattr(self, name), allow_zero=allow_zero)

    @property
    def ideal(self) -> bool:
        """True for the exact single integrator without measurement noise (the planner's model)."""
        return self.kind == "ideal" and self.measurement_noise_m == 0.0

    def with_kind(self, kind: str) -> PlantSpec:
        """This plant as ``kind``: itself if of that kind, else that kind's defaults with this plant's
        common fields (wind, noise, margin, samples per step; a wind on the ideal plant is an error)."""
        if kind == self.kind:
            return self
        common = {f.name: getattr(self, f.name) for f in dataclasses.fields(PlantSpec)}
        return plant_spec(kind, **common)

    def robustness(
        self, dim: int, dt_s: float, a_max_mps2: float | None, loop_modelled: bool = False
    ) -> Robustness:
        """The margin and acceleration bound the planner uses for this plant (module
        :mod:`mpcform.sim.margin`): zero for the ideal plant; otherwise ``margin_m`` if given, else
        the plant's margin over one control interval of ``dt_s`` with ``a_max_mps2`` (None: the
        plant's default); with ``loop_modelled`` (the MPC's rows model the plant's velocity loop at
        the interval ends, :mod:`mpcform.mpc.velocity_loop`) only what that model leaves out
        (:func:`mpcform.sim.margin.modelled_margin`). Measurement noise is not part of it. The rows'
        growth is ``margin_growth_m`` if given, else the wind's (:func:`mpcform.sim.margin.wind_growth`)."""
        if self.kind == "ideal":
            return Robustness(self.margin_m or 0.0, a_max_mps2, growth_m=self.margin_growth_m or 0.0)
        if a_max_mps2 is not None and not np.isfinite(a_max_mps2):
            raise ValidationError(
                "limits.a_max",
                f"inf (no bound) applies to the ideal plant only: the {self.kind} plant's margin "
                "assumes a bound on command changes (omit a_max for the platform's default)",
            )
        from mpcform.sim.margin import default_a_max, modelled_margin, plant_margin, wind_growth

        plant = self.build(1, dim)
        a_max = default_a_max(plant) if a_max_mps2 is None else a_max_mps2
        margin = plant_margin(plant, dt_s, a_max)
        loop = tuple((a, b, c, axes) for a, b, _, c, axes in plant.velocity_loops())
        computed = margin.norm_m
        if loop_modelled:  # the interval ends are modelled: the wind, the bend within, the remainder
            computed = float(np.linalg.norm(modelled_margin(plant, dt_s, a_max, margin)))
        chosen = computed if self.margin_m is None else self.margin_m
        growth = wind_growth(plant, dt_s) if self.margin_growth_m is None else self.margin_growth_m
        if not (np.isfinite(chosen) and np.isfinite(growth)):
            raise self._unbounded(dt_s)
        return Robustness(chosen, a_max, margin.valid_speed_mps, loop, growth)

    def _unbounded(self, dt_s: float) -> ValidationError:
        """The error of a plant that leaves the MPC no finite robust margin, naming the key that
        does: an unclipped gust, else the plant's own loop."""
        if self.wind is not None and not np.all(np.isfinite(self.wind.speed_bound_mps())):
            return ValidationError(
                "plant.wind.gust_bound",
                "an unclipped gust (inf) leaves the MPC no finite robust margin: give a bound "
                "(the default is 3 gust_std) or set plant.margin and plant.margin_growth",
            )
        own = [f.name for f in dataclasses.fields(self) if f.name not in COMMON_FIELDS]
        params = ", ".join(f"{scenario_key(name)} = {getattr(self, name)!r}" for name in own)
        return ValidationError(
            f"plant.{scenario_key(own[0])}" if own else "plant",
            f"the {self.kind} plant ({params}) leaves the MPC no finite robust margin at dt = {dt_s:g} s: "
            "expected a velocity loop a drone can follow (or set plant.margin)",
        )

    def build(self, n: int, dim: int, seed: int | np.random.SeedSequence = 0) -> Plant:
        """The plant for ``n`` drones in ``dim`` dimensions; ``seed`` feeds its wind and noise."""
        return self._plant(
            n,
            dim,
            wind=self.wind,
            noise_std_m=self.measurement_noise_m,
            seed=seed,
            samples_per_step=self.samples_per_step,
        )

    @abstractmethod
    def _plant(self, n: int, dim: int, **common: Any) -> Plant:
        """The plant of this kind, with the ``common`` keywords of :class:`~mpcform.sim.plants.Plant`."""


@dataclass(frozen=True)
class IdealPlantSpec(PlantSpec):
    """The exact single integrator the planner assumes; it takes no wind."""

    kind: ClassVar[str] = "ideal"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.wind is not None:
            raise ValidationError(
                "plant.wind",
                "the ideal plant is the planner's own model and takes no wind: choose "
                "plant.kind = lag, second_order or quadrotor",
            )

    def _plant(self, n: int, dim: int, **common: Any) -> Plant:
        return IdealPlant(n, dim, **common)


@dataclass(frozen=True)
class LagPlantSpec(PlantSpec):
    """A first-order velocity loop of time constant ``time_constant_s`` [s]."""

    kind: ClassVar[str] = "lag"
    time_constant_s: float = 0.1

    def __post_init__(self) -> None:
        super().__post_init__()
        self._positive("time_constant_s")

    def _plant(self, n: int, dim: int, **common: Any) -> Plant:
        return lag_plant(n, dim, self.time_constant_s, **common)


@dataclass(frozen=True)
class SecondOrderPlantSpec(PlantSpec):
    """A damped velocity loop per axis: ``damping`` and ``natural_frequency_rad_s`` [rad/s]; the
    vertical axis's ``damping_z`` and ``natural_frequency_z_rad_s`` (None: the same)."""

    kind: ClassVar[str] = "second_order"
    damping: float = 0.7
    natural_frequency_rad_s: float = 6.0
    damping_z: float | None = None
    natural_frequency_z_rad_s: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        self._positive("damping")
        self._positive("natural_frequency_rad_s")
        for name in ("damping_z", "natural_frequency_z_rad_s"):
            if getattr(self, name) is not None:
                self._positive(name)

    def _plant(self, n: int, dim: int, **common: Any) -> Plant:
        return second_order_plant(
            n,
            dim,
            self.damping,
            self.natural_frequency_rad_s,
            zeta_z=self.damping_z,
            omega_z_rad_s=self.natural_frequency_z_rad_s,
            **common,
        )


@dataclass(frozen=True)
class QuadrotorPlantSpec(PlantSpec):
    """The quadrotor (:mod:`mpcform.sim.quadrotor`): drone-models ``platform`` and ``model``, the
    inner rate ``rate_hz`` [Hz] and the height ``altitude_m`` [m] a planar flight holds."""

    kind: ClassVar[str] = "quadrotor"
    platform: str = QuadrotorSpec.platform
    model: str = QuadrotorSpec.model
    rate_hz: float = QuadrotorSpec.rate_hz
    altitude_m: float = QuadrotorSpec.altitude_m

    def __post_init__(self) -> None:
        super().__post_init__()
        self._positive("rate_hz")
        if not 0.0 <= self.altitude_m < math.inf:
            raise ValidationError(
                "plant.altitude", f"expected a finite height >= 0 [m], got {self.altitude_m!r}"
            )

    def _plant(self, n: int, dim: int, **common: Any) -> Plant:
        spec = QuadrotorSpec(self.platform, self.model, self.rate_hz, altitude_m=self.altitude_m)
        return QuadrotorPlant(n, dim, spec, **common)


@dataclass(frozen=True)
class CrazyflowPlantSpec(PlantSpec):
    """crazyflow (:mod:`mpcform.sim.crazyflow`): the Crazyflie model ``drone``, its physics and
    Mellinger controller rates ``physics_rate_hz`` and ``control_rate_hz`` [Hz] and the height
    ``altitude_m`` [m] a planar flight holds. The planner models it, and sizes its margin, as the
    quadrotor plant of the same platform (the hover linearisation of a Crazyflie's loop)."""

    kind: ClassVar[str] = "crazyflow"
    drone: str = "cf2x_L250"
    physics_rate_hz: int = 500
    control_rate_hz: int = 100
    altitude_m: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_settings(
            self.drone, self.physics_rate_hz, self.control_rate_hz, self.altitude_m, self.wind is not None
        )

    def robustness(
        self, dim: int, dt_s: float, a_max_mps2: float | None, loop_modelled: bool = False
    ) -> Robustness:
        """The quadrotor plant's of the same platform (class docstring)."""
        common = {f.name: getattr(self, f.name) for f in dataclasses.fields(PlantSpec)}
        model = QuadrotorPlantSpec(platform=self.drone, altitude_m=self.altitude_m, **common)
        return model.robustness(dim, dt_s, a_max_mps2, loop_modelled)

    def _plant(self, n: int, dim: int, **common: Any) -> Plant:
        return CrazyflowPlant(
            n,
            dim,
            drone=self.drone,
            physics_hz=self.physics_rate_hz,
            control_hz=self.control_rate_hz,
            altitude_m=self.altitude_m,
            **common,
        )


PLANT_SPECS: dict[str, type[PlantSpec]] = {
    cls.kind: cls
    for cls in (IdealPlantSpec, LagPlantSpec, SecondOrderPlantSpec, QuadrotorPlantSpec, CrazyflowPlantSpec)
}
"""The spec class of every plant kind, in the order of :data:`mpcform.sim.plants.KINDS`."""


def plant_spec(kind: str, **fields: Any) -> PlantSpec:
    """The spec of plant ``kind`` with ``fields`` (the others at their defaults)."""
    if kind not in PLANT_SPECS:
        raise ValidationError("plant.kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
    return PLANT_SPECS[kind](**fields)
