"""PlantSpec: the [plant] table's validation and the one factory of plants."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.sim.plant_spec import PlantSpec
from mpcform.sim.plants import IdealPlant, LinearPlant
from mpcform.sim.wind import Wind


def test_build_makes_each_linear_kind_and_the_ideal_plant() -> None:
    assert isinstance(PlantSpec().build(3, 2), IdealPlant)
    lag = PlantSpec("lag", time_constant_s=0.2).build(3, 3, seed=1)
    assert isinstance(lag, LinearPlant) and lag.kind == "lag"
    second = PlantSpec("second_order", damping=0.7, natural_frequency_rad_s=6.0).build(4, 3)
    assert second.kind == "second_order"
    lag.reset(np.zeros((3, 3)))
    samples = lag.advance(np.ones((3, 3)), 0.1)
    assert samples.p_true_m.shape == (11, 3, 3) and np.all(np.isfinite(samples.p_true_m))


def test_ideal_is_only_the_noise_free_single_integrator() -> None:
    assert PlantSpec().ideal
    assert not PlantSpec(measurement_noise_m=0.01).ideal
    assert not PlantSpec("lag").ideal


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"kind": "rocket"}, "plant.kind"),
        ({"kind": "lag", "time_constant_s": -0.1}, "plant.time_constant"),
        ({"kind": "second_order", "damping": 0.0}, "plant.damping"),
        ({"natural_frequency_rad_s": float("nan")}, "plant.natural_frequency"),
        ({"damping_z": -1.0}, "plant.damping_z"),
        ({"rate_hz": 0.0}, "plant.rate"),
        ({"altitude_m": float("inf")}, "plant.altitude"),
        ({"measurement_noise_m": -0.1}, "plant.measurement_noise"),
        ({"margin_m": -0.1}, "plant.margin"),
        ({"kind": "ideal", "wind": Wind([1.0, 0.0])}, "plant.wind"),
    ],
)
def test_bad_plant_declarations_name_their_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValidationError, match=field):
        PlantSpec(**kwargs)


def test_wind_of_the_wrong_dimension_is_refused_when_built() -> None:
    with pytest.raises(ValidationError, match="wind.mean"):
        PlantSpec("lag", wind=Wind([1.0, 0.0, 0.0])).build(2, 2)
