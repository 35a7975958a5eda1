"""The [plant] table: kinds, wind, the migrated simulation.lag, and errors that name the key."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from helpers import tiny_swap_toml
from saved_runs import SCENARIOS

from mpcform.errors import ScenarioError
from mpcform.scenario.load import load_scenario, scenario_from_dict
from mpcform.scenario.plant import with_plant_kind
from mpcform.scenario.schema import TABLES
from mpcform.sim.plant_spec import (
    PLANT_SPECS,
    IdealPlantSpec,
    LagPlantSpec,
    QuadrotorPlantSpec,
    SecondOrderPlantSpec,
    scenario_key,
)

try:
    import tomllib
except ImportError:  # pragma: no cover - Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]


LAG_WIND = '[plant]\nkind = "lag"\n[plant.wind]\nmean = [1.0, 0.0]\n'


def scenario(extra: str) -> dict:
    return tomllib.loads(tiny_swap_toml("plant", 1.5, 8, 2.0) + extra)


def test_no_table_is_the_ideal_plant() -> None:
    assert scenario_from_dict(scenario("")).plant.ideal
    assert scenario_from_dict(scenario("")).plant == IdealPlantSpec()


@pytest.mark.parametrize(
    ("kind", "spec"),
    [
        ("ideal", IdealPlantSpec()),
        ("lag", LagPlantSpec()),
        ("second_order", SecondOrderPlantSpec()),
        ("quadrotor", QuadrotorPlantSpec()),
    ],
)
def test_a_minimal_table_takes_the_specs_defaults(kind: str, spec: object) -> None:
    assert scenario_from_dict(scenario(f'[plant]\nkind = "{kind}"\n')).plant == spec


def test_the_key_reference_states_the_specs_fields_and_defaults() -> None:
    """Every [plant] key that applies to a kind is a field of its spec with the same default (the
    key reference reads it there), and every field but samples_per_step (and the wind of the ideal
    plant) is a key."""
    table = TABLES["plant"]
    for kind, cls in PLANT_SPECS.items():
        fields = {scenario_key(f.name): f for f in dataclasses.fields(cls)}
        keys = {k.name: k for k in table.keys if k.name != "kind" and (not k.when or kind in k.when)}
        not_keys = {"samples_per_step"} | ({"wind"} if kind == "ideal" else set())  # no wind: refused
        assert set(keys) == set(fields) - not_keys, kind
        for name, key in keys.items():
            assert key.default == fields[name].default, (kind, name)
    assert table.key("kind").default == IdealPlantSpec.kind


def test_plant_override_keeps_the_table_on_its_own_kind_and_defaults_another() -> None:
    lag = scenario_from_dict(
        scenario('[plant]\nkind = "lag"\ntime_constant = 0.2\nmeasurement_noise = 0.01\n')
    )
    assert with_plant_kind(lag, "lag").plant == LagPlantSpec(0.2, measurement_noise_m=0.01)
    assert with_plant_kind(lag, "second_order").plant == SecondOrderPlantSpec(measurement_noise_m=0.01)
    windy = scenario_from_dict(scenario(LAG_WIND))
    with pytest.raises(ScenarioError, match="--plant") as err:
        with_plant_kind(windy, "ideal")
    assert "takes no wind" in str(err.value)
    odd = scenario('[plant]\nkind = "lag"\n')
    odd["simulation"]["dt"] = 0.0125  # 6.25 inner steps of 500 Hz
    with pytest.raises(ScenarioError, match="plant.rate"):
        with_plant_kind(scenario_from_dict(odd), "quadrotor")


def test_lag_second_order_and_quadrotor_with_wind() -> None:
    lag = scenario_from_dict(scenario('[plant]\nkind = "lag"\ntime_constant = 0.2\n')).plant
    assert lag.kind == "lag" and lag.time_constant_s == 0.2
    text = '[plant]\nkind = "second_order"\ndamping = 0.5\nnatural_frequency = 8.0\n'
    second = scenario_from_dict(scenario(text)).plant
    assert (second.damping, second.natural_frequency_rad_s) == (0.5, 8.0)
    text = (
        '[plant]\nkind = "quadrotor"\nplatform = "cf2x_P250"\nrate = 500\n'
        '[plant.wind]\nmean = [1.0, 0.0]\ngust_std = 0.5\ngust_time = 1.0\ngust_field = "shared"\n'
    )
    quad = scenario_from_dict(scenario(text)).plant
    assert quad.platform == "cf2x_P250" and quad.wind is not None
    np.testing.assert_array_equal(quad.wind.mean_mps, [1.0, 0.0])
    np.testing.assert_array_equal(quad.wind.gust_bound_mps, [1.5, 1.5])  # 3 gust_std
    unclipped = scenario('[plant]\nkind = "lag"\n[plant.wind]\nmean = [0.0, 0.0]\ngust_std = 0.5\n')
    unclipped["plant"]["wind"]["gust_bound"] = math.inf
    unclipped["plant"]["margin"] = 0.1  # the MPC needs finite ones: no gust bound gives none
    unclipped["plant"]["margin_growth"] = 0.01
    assert np.all(np.isinf(scenario_from_dict(unclipped).plant.wind.gust_bound_mps))


@pytest.mark.parametrize(
    ("text", "field", "says"),
    [
        ("[simulation]\nlag = 0.1\n", "simulation.lag", 'kind = "lag"'),
        ('[plant]\nkind = "rocket"\n', "plant.kind", "quadrotor"),
        ('[plant]\nkind = "lag"\ntime_constant = -0.1\n', "plant.time_constant", "> 0"),
        ('[plant]\nkind = "second_order"\ndamping = 0.0\n', "plant.damping", "> 0"),
        ('[plant]\nkind = "quadrotor"\nplatform = "cf9"\n', "plant.platform", "cf2x_L250"),
        ('[plant]\nkind = "quadrotor"\nrate = 5\n', "plant.rate", "multiple"),
        ('[plant]\nkind = "quadrotor"\nrate = 505\n', "plant.rate", "multiple"),
        ('[plant]\nkind = "quadrotor"\naltitude = -5.0\n', "plant.altitude", ">= 0 [m], got -5.0"),
        ('[plant]\nkind = "lag"\ndamping = 0.7\n', "plant.damping", "does not apply"),
        ('[plant]\nkind = "second_order"\nrate = 500\n', "plant.rate", "does not apply"),
        ('[plant]\nkind = "quadrotor"\ntime_constant = 0.1\n', "plant.time_constant", "does not apply"),
        ("[plant]\nmargin = 0.1\ndamping = 0.7\n", "plant.damping", "does not apply"),
        ('[plant]\nkind = "lag"\n[plant.wind]\nmean = [1.0, 0.0, 0.0]\n', "plant.wind.mean", "2 finite"),
        ('[plant]\nkind = "lag"\n[plant.wind]\nmean = [1.0, nan]\n', "plant.wind.mean", "finite"),
        (f"{LAG_WIND}gust_bound = -1.0\n", "plant.wind.gust_bound", ">= 0"),
        (f"{LAG_WIND}gusts = 1.0\n", "plant.wind.gusts", "unknown"),
        ("[plant]\n[plant.wind]\nmean = [1.0, 0.0]\n", "plant.wind", "does not apply"),
        ("[plant]\nmeasurement_noise = -0.1\n", "plant.measurement_noise", ">= 0"),
    ],
)
def test_bad_plant_keys_name_the_key(text: str, field: str, says: str) -> None:
    data = scenario(text) if not text.startswith("[simulation]") else _with_sim_lag()
    with pytest.raises(ScenarioError, match=field) as err:
        scenario_from_dict(data)
    assert says in str(err.value)


def _with_sim_lag() -> dict:
    data = scenario("")
    data["simulation"]["lag"] = 0.1
    return data


def test_an_unclipped_gust_names_its_key_not_the_margin(tmp_path) -> None:  # noqa: ANN001
    """``gust_bound = inf`` is documented, but the MPC then has no finite margin: the error names
    ``plant.wind.gust_bound`` (it named ``plant.margin``, a key the user never wrote)."""
    from mpcform.errors import ScenarioError
    from mpcform.scenario.load import load_scenario

    path = tmp_path / "w.toml"
    text = (SCENARIOS / "swap_spatial_12_quadrotor_wind.toml").read_text()
    path.write_text(text.rstrip() + "\ngust_bound = inf\n")
    with pytest.raises(ScenarioError, match=r"plant.wind.gust_bound: an unclipped gust"):
        load_scenario(path)
    path.write_text(text.replace("gust_std = 0.5", "gust_std = -1"))
    with pytest.raises(ScenarioError, match=r"gust_std: expected a finite number >= 0, got -1$"):
        load_scenario(path)


def test_crazyflow_plans_a_crazyflies_climb_rate_in_space_unless_the_file_sets_one() -> None:
    from mpcform.world.limits import PLATFORM_CLIMB_MPS, PLATFORM_TRACKING_M

    spatial = load_scenario(SCENARIOS / "swap_spatial_12.toml")
    flown = with_plant_kind(spatial, "crazyflow")
    assert flown.limits.v_max_z_mps == PLATFORM_CLIMB_MPS == 0.7
    assert flown.limits.tracking_m == PLATFORM_TRACKING_M
    own = dataclasses.replace(spatial, limits=dataclasses.replace(spatial.limits, v_max_z_mps=0.9))
    assert with_plant_kind(own, "crazyflow").limits.v_max_z_mps == 0.9
    assert with_plant_kind(spatial, "quadrotor").limits.v_max_z_mps is None
    planar = with_plant_kind(load_scenario(SCENARIOS / "swap_planar_8.toml"), "crazyflow")
    assert planar.limits.v_max_z_mps is None
