"""The ``[plant]`` table (and ``[plant.wind]``) -> a :class:`~mpcform.sim.plant_spec.PlantSpec` of its
kind, from the keys given (the others take the spec's defaults)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from mpcform.control.setpoints import ticks_per_interval
from mpcform.errors import ScenarioError, ValidationError
from mpcform.scenario.parse import as_scenario_error, parse_table
from mpcform.scenario.spec import Scenario
from mpcform.sim.plant_spec import (
    PLANT_SPECS,
    CrazyflowPlantSpec,
    PlantSpec,
    QuadrotorPlantSpec,
    plant_spec,
    scenario_key,
)
from mpcform.sim.wind import GUST_FIELDS, Wind
from mpcform.world.limits import PLATFORM_CLIMB_MPS

WIND_KEYS = ("mean", "gust_std", "gust_time", "gust_bound", "gust_field")
RATE_RTOL = 1e-9
"""The inner rate must be a multiple of the control rate to this relative tolerance."""


def parse_plant(data: Mapping[str, Any], dim: int, dt_s: float) -> PlantSpec:
    """The scenario's plant (the ideal plant when the table is absent), checked against ``dt_s``; only
    the keys the table gives are passed, so the others take the spec class's defaults."""
    raw_sim = data.get("simulation")
    if isinstance(raw_sim, Mapping) and "lag" in raw_sim:
        raise ScenarioError(
            "simulation.lag",
            f'moved: write [plant] with kind = "lag" and time_constant = '
            f"{raw_sim['lag']!r} (the same time constant [s]); simulation.lag is no longer read",
        )
    p = parse_table(data, "plant", dim)
    given = data.get("plant") or {}
    fields = {scenario_key(f.name): f.name for f in dataclasses.fields(PLANT_SPECS[p["kind"]])}
    values = {fields[key]: _wind(p[key], dim) if key == "wind" else p[key] for key in given if key != "kind"}
    with as_scenario_error("plant"):
        spec = plant_spec(p["kind"], **values)
    check_plant_rates(spec, dt_s)
    return spec


def check_plant_rates(spec: PlantSpec, dt_s: float) -> None:
    """A plant's inner rates must be whole multiples of the control rate ``1 / dt``."""
    if isinstance(spec, QuadrotorPlantSpec):
        check_rate(spec.rate_hz, dt_s)
    if isinstance(spec, CrazyflowPlantSpec):
        with as_scenario_error("plant"):
            ticks_per_interval(dt_s, spec.control_rate_hz, "plant.control_rate")


def check_rate(rate_hz: float, dt_s: float) -> None:
    """The quadrotor's inner rate must be a whole multiple (>= 1) of the control rate ``1 / dt``."""
    ratio = rate_hz * dt_s
    if ratio < 1.0 - RATE_RTOL or abs(ratio - round(ratio)) > RATE_RTOL * ratio:
        raise ScenarioError(
            "plant.rate",
            f"expected a multiple of the control rate 1 / dt = {1.0 / dt_s:g} Hz, "
            f"got {rate_hz:g} Hz ({ratio:.6g} inner steps per control step)",
        )


def with_plant_kind(scenario: Scenario, kind: str) -> Scenario:
    """``scenario`` flown on a plant of another ``kind`` (``mpcform run --plant``), the table's other
    keys kept (a wind on the ideal plant is an error); on crazyflow planned with the tracking
    allowance (:meth:`~mpcform.scenario.spec.Scenario.flyable`)."""
    try:
        plant = scenario.plant.with_kind(kind)
    except ValidationError as exc:
        raise ScenarioError("--plant", str(exc).removeprefix(f"{exc.field}: ")) from None
    check_plant_rates(plant, scenario.simulation.dt_s)
    return planned_for_its_plant(dataclasses.replace(scenario, plant=plant))


def planned_for_its_plant(scenario: Scenario) -> Scenario:
    """``scenario`` as its plant needs it planned: on crazyflow, which flies the plan as a
    Crazyflie's setpoints, with the tracking allowance (:meth:`~mpcform.scenario.spec.Scenario.flyable`)
    and, in space, a Crazyflie's vertical speed bound where ``limits.v_max_z`` is unset
    (:data:`~mpcform.world.limits.PLATFORM_CLIMB_MPS`)."""
    if scenario.plant.kind != "crazyflow":
        return scenario
    flown = scenario.flyable()
    lim = flown.limits
    if flown.dim == 3 and lim.v_max_mps is not None and lim.v_max_z_mps is None:
        flown = dataclasses.replace(flown, limits=dataclasses.replace(lim, v_max_z_mps=PLATFORM_CLIMB_MPS))
    return flown


def _wind(raw: Any, dim: int) -> Wind | None:
    if raw is None:
        return None
    if not isinstance(raw, Mapping):
        raise ScenarioError("plant.wind", f"expected a table [plant.wind], got {raw!r}")
    unknown = sorted(set(raw) - set(WIND_KEYS))
    if unknown:
        raise ScenarioError(f"plant.wind.{unknown[0]}", f"unknown key; expected {', '.join(WIND_KEYS)}")
    if "mean" not in raw:
        raise ScenarioError("plant.wind.mean", f"missing: the mean wind, {dim} numbers [m/s]")
    mean = raw["mean"]
    if not isinstance(mean, list) or len(mean) != dim or not all(_finite(x) for x in mean):
        raise ScenarioError("plant.wind.mean", f"expected {dim} finite numbers [m/s], got {mean!r}")
    given: dict[str, Any] = {}  # the Wind's fields given; the others take its defaults
    for key, low, name in (
        ("gust_std", 0.0, "gust_std_mps"),
        ("gust_time", None, "gust_time_s"),
        ("gust_bound", 0.0, "gust_bound_mps"),
    ):
        if key in raw:
            x = raw[key]
            ok = isinstance(x, int | float) and not isinstance(x, bool) and not math.isnan(x)
            if not ok or (low is None and not (x > 0 and math.isfinite(x))) or (low is not None and x < low):
                want = {"gust_time": "a finite number > 0", "gust_std": "a finite number >= 0"}.get(
                    key, "a number >= 0 (inf allowed)"
                )
                raise ScenarioError(f"plant.wind.{key}", f"expected {want}, got {x!r}")
            if key == "gust_std" and not math.isfinite(x):
                raise ScenarioError("plant.wind.gust_std", f"expected a finite number >= 0, got {x!r}")
            given[name] = float(x)
    if "gust_field" in raw:
        field = raw["gust_field"]
        if field not in GUST_FIELDS:
            raise ScenarioError(
                "plant.wind.gust_field", f"expected {' or '.join(GUST_FIELDS)}, got {field!r}"
            )
        given["gust_field"] = field
    with as_scenario_error("plant"):
        return Wind(np.array(mean, dtype=float), **given)


def _finite(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
