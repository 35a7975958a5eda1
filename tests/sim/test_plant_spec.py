"""The plant specs: one dataclass per kind, their validation, and the one factory of plants."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.sim.plant_spec import (
    PLANT_SPECS,
    CrazyflowPlantSpec,
    IdealPlantSpec,
    LagPlantSpec,
    PlantSpec,
    QuadrotorPlantSpec,
    SecondOrderPlantSpec,
    plant_spec,
    scenario_key,
)
from mpcform.sim.plants import KINDS, IdealPlant, LinearPlant
from mpcform.sim.quadrotor import QuadrotorSpec
from mpcform.sim.wind import Wind


def test_build_makes_each_linear_kind_and_the_ideal_plant() -> None:
    assert isinstance(IdealPlantSpec().build(3, 2), IdealPlant)
    lag = LagPlantSpec(time_constant_s=0.2).build(3, 3, seed=1)
    assert isinstance(lag, LinearPlant) and lag.kind == "lag"
    second = SecondOrderPlantSpec(damping=0.7, natural_frequency_rad_s=6.0).build(4, 3)
    assert second.kind == "second_order"
    lag.reset(np.zeros((3, 3)))
    samples = lag.advance(np.ones((3, 3)), 0.1)
    assert samples.p_true_m.shape == (11, 3, 3) and np.all(np.isfinite(samples.p_true_m))


def test_one_class_per_kind_in_the_order_of_the_kinds() -> None:
    assert tuple(PLANT_SPECS) == KINDS
    assert all(PLANT_SPECS[kind].kind == kind for kind in KINDS)
    assert type(plant_spec("lag", time_constant_s=0.3)) is LagPlantSpec
    with pytest.raises(TypeError):
        PlantSpec()  # type: ignore[abstract]


def test_defaults_are_the_field_defaults_and_the_quadrotor_spec() -> None:
    assert LagPlantSpec().time_constant_s == 0.1
    assert (SecondOrderPlantSpec().damping, SecondOrderPlantSpec().natural_frequency_rad_s) == (0.7, 6.0)
    quad, inner = QuadrotorPlantSpec(), QuadrotorSpec()
    assert (quad.platform, quad.model, quad.rate_hz, quad.altitude_m) == (
        inner.platform,
        inner.model,
        inner.rate_hz,
        inner.altitude_m,
    )
    assert plant_spec("second_order") == SecondOrderPlantSpec()


def test_common_fields_are_keyword_only_and_the_kind_fields_positional() -> None:
    assert LagPlantSpec(0.3, measurement_noise_m=0.01) == LagPlantSpec(
        time_constant_s=0.3, measurement_noise_m=0.01
    )
    with pytest.raises(TypeError):
        IdealPlantSpec(None)  # type: ignore[misc]


def test_scenario_keys_drop_the_units() -> None:
    keys = {scenario_key(f.name) for cls in PLANT_SPECS.values() for f in dataclasses.fields(cls)}
    assert keys == {
        "wind",
        "measurement_noise",
        "margin",
        "margin_growth",
        "samples_per_step",
        "time_constant",
        "damping",
        "natural_frequency",
        "damping_z",
        "natural_frequency_z",
        "platform",
        "model",
        "rate",
        "altitude",
        "drone",
        "physics_rate",
        "control_rate",
    }


def test_ideal_is_only_the_noise_free_single_integrator() -> None:
    assert IdealPlantSpec().ideal
    assert not IdealPlantSpec(measurement_noise_m=0.01).ideal
    assert not LagPlantSpec().ideal


def test_with_kind_keeps_the_common_fields_and_takes_the_new_kinds_defaults() -> None:
    wind = Wind([1.0, 0.0])
    lag = LagPlantSpec(time_constant_s=0.3, wind=wind, measurement_noise_m=0.01, margin_m=0.05)
    assert lag.with_kind("lag") is lag
    second = lag.with_kind("second_order")
    assert second == SecondOrderPlantSpec(wind=wind, measurement_noise_m=0.01, margin_m=0.05)
    assert second.with_kind("lag") == LagPlantSpec(wind=wind, measurement_noise_m=0.01, margin_m=0.05)
    with pytest.raises(ValidationError, match="plant.wind"):
        lag.with_kind("ideal")
    with pytest.raises(ValidationError, match="plant.kind"):
        lag.with_kind("rocket")


@pytest.mark.parametrize(
    ("kind", "kwargs", "field"),
    [
        ("rocket", {}, "plant.kind"),
        ("lag", {"time_constant_s": -0.1}, "plant.time_constant"),
        ("second_order", {"damping": 0.0}, "plant.damping"),
        ("second_order", {"natural_frequency_rad_s": float("nan")}, "plant.natural_frequency"),
        ("second_order", {"damping_z": -1.0}, "plant.damping_z"),
        ("second_order", {"natural_frequency_z_rad_s": 0.0}, "plant.natural_frequency_z"),
        ("quadrotor", {"rate_hz": 0.0}, "plant.rate"),
        ("quadrotor", {"altitude_m": float("inf")}, "plant.altitude"),
        ("quadrotor", {"altitude_m": -5.0}, "plant.altitude"),
        ("ideal", {"measurement_noise_m": -0.1}, "plant.measurement_noise"),
        ("lag", {"margin_m": -0.1}, "plant.margin"),
        ("lag", {"margin_growth_m": -0.1}, "plant.margin_growth"),
        ("ideal", {"wind": Wind([1.0, 0.0])}, "plant.wind"),
    ],
)
def test_bad_plant_declarations_name_their_field(kind: str, kwargs: dict, field: str) -> None:
    with pytest.raises(ValidationError, match=field):
        plant_spec(kind, **kwargs)


@pytest.mark.parametrize(("cls", "name"), [(IdealPlantSpec, "time_constant_s"), (LagPlantSpec, "damping")])
def test_a_field_of_another_kind_is_refused(cls: type[PlantSpec], name: str) -> None:
    with pytest.raises(TypeError, match=name):
        cls(**{name: 0.5})


def test_wind_of_the_wrong_dimension_is_refused_when_built() -> None:
    with pytest.raises(ValidationError, match="wind.mean"):
        LagPlantSpec(wind=Wind([1.0, 0.0, 0.0])).build(2, 2)


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        ({"physics_rate_hz": 450}, "plant.physics_rate: expected a multiple of plant.control_rate"),
        ({"control_rate_hz": 0}, "plant.control_rate: expected an integer >= 1"),
        ({"drone": "cf3"}, "plant.drone: expected one of cf2x_L250"),
        ({"altitude_m": 0.0}, "plant.altitude: expected a finite height > 0"),
    ],
)
def test_crazyflow_spec_refuses_bad_fields(fields: dict, match: str) -> None:
    with pytest.raises(ValidationError, match=match):
        CrazyflowPlantSpec(**fields)


def test_crazyflow_is_planned_as_the_quadrotor_of_its_platform() -> None:
    crazy = CrazyflowPlantSpec(drone="cf2x_P250").robustness(3, 0.1, None, True)
    quad = QuadrotorPlantSpec(platform="cf2x_P250").robustness(3, 0.1, None, True)
    assert (crazy.margin_m, crazy.a_max_mps2, crazy.valid_speed_mps) == (
        quad.margin_m,
        quad.a_max_mps2,
        quad.valid_speed_mps,
    )
    for (a, b, c, axes), (qa, qb, qc, qaxes) in zip(crazy.loop, quad.loop, strict=True):
        assert axes == qaxes and np.array_equal(a, qa) and np.array_equal(b, qb) and np.array_equal(c, qc)


def test_the_rows_growth_comes_from_the_wind_unless_the_file_gives_it() -> None:
    """``plant.margin_growth`` overrides the wind's growth (0 turns it off); calm air has none."""
    gusty = Wind([1.0, 0.0], gust_std_mps=0.5)
    assert LagPlantSpec(0.2).robustness(2, 0.1, None, True).growth_m == 0.0
    computed = LagPlantSpec(0.2, wind=gusty).robustness(2, 0.1, None, True).growth_m
    assert computed > 0.0
    assert LagPlantSpec(0.2, wind=gusty, margin_growth_m=0.0).robustness(2, 0.1, None, True).growth_m == 0.0
    assert IdealPlantSpec(margin_growth_m=0.01).robustness(2, 0.1, None).growth_m == 0.01


@pytest.mark.parametrize(
    ("spec", "field"),
    [
        (LagPlantSpec(time_constant_s=1e-300), "plant.time_constant"),  # no wind: not the gust's key
        (LagPlantSpec(0.3, wind=Wind([1.0, 0.0], 0.3, gust_bound_mps=math.inf)), "plant.wind.gust_bound"),
        (
            LagPlantSpec(0.3, wind=Wind([1.0, 0.0], 0.3, gust_bound_mps=math.inf), margin_m=0.1),
            "plant.wind.gust_bound",
        ),
    ],
)
def test_a_plant_that_leaves_no_finite_margin_names_its_own_key(spec: PlantSpec, field: str) -> None:
    """The margin and the rows' growth are derived from the plant: an error names the key the user
    wrote (never ``limits.tube_growth``, a bound the planner derives)."""
    with pytest.raises(ValidationError, match=rf"^{field}: .*no finite robust margin"):
        spec.robustness(2, 0.1, None)
