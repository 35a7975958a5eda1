"""The ``[plant]`` table (and ``[plant.wind]``) -> :class:`~mpcform.sim.plant_spec.PlantSpec`."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from mpcform.errors import ScenarioError, ValidationError
from mpcform.scenario.parse import as_scenario_error, parse_table
from mpcform.scenario.spec import Scenario
from mpcform.sim.plant_spec import PlantSpec
from mpcform.sim.wind import GUST_FIELDS, Wind

WIND_KEYS = ("mean", "gust_std", "gust_time", "gust_bound", "gust_field")
RATE_RTOL = 1e-9
"""The inner rate must be a multiple of the control rate to this relative tolerance."""


def parse_plant(data: Mapping[str, Any], dim: int, dt_s: float) -> PlantSpec:
    """The scenario's plant (the ideal plant when the table is absent), checked against ``dt_s``."""
    raw_sim = data.get("simulation")
    if isinstance(raw_sim, Mapping) and "lag" in raw_sim:
        raise ScenarioError(
            "simulation.lag",
            f'moved: write [plant] with kind = "lag" and time_constant = '
            f"{raw_sim['lag']!r} (the same time constant [s]); simulation.lag is no longer read",
        )
    p = parse_table(data, "plant", dim)
    if p["kind"] == "quadrotor":
        check_rate(p["rate"], dt_s)
    with as_scenario_error("plant"):
        return PlantSpec(
            kind=p["kind"],
            time_constant_s=p["time_constant"] or PlantSpec.time_constant_s,
            damping=p["damping"] or PlantSpec.damping,
            natural_frequency_rad_s=p["natural_frequency"] or PlantSpec.natural_frequency_rad_s,
            damping_z=p["damping_z"],
            natural_frequency_z_rad_s=p["natural_frequency_z"],
            platform=p["platform"] or PlantSpec.platform,
            model=p["model"] or PlantSpec.model,
            rate_hz=p["rate"] or PlantSpec.rate_hz,
            altitude_m=PlantSpec.altitude_m if p["altitude"] is None else p["altitude"],
            wind=_wind(p["wind"], dim),
            measurement_noise_m=p["measurement_noise"],
            margin_m=p["margin"],
        )


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
    keys kept (a wind on the ideal plant is an error)."""
    try:
        plant = dataclasses.replace(scenario.plant, kind=kind)
    except ValidationError as exc:
        raise ScenarioError("--plant", str(exc).removeprefix(f"{exc.field}: ")) from None
    if kind == "quadrotor":
        check_rate(plant.rate_hz, scenario.simulation.dt_s)
    return dataclasses.replace(scenario, plant=plant)


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
    numbers = {}
    for key, low in (("gust_std", 0.0), ("gust_time", None), ("gust_bound", 0.0)):
        if key in raw:
            x = raw[key]
            ok = isinstance(x, int | float) and not isinstance(x, bool) and not math.isnan(x)
            if not ok or (low is None and not (x > 0 and math.isfinite(x))) or (low is not None and x < low):
                want = "a finite number > 0" if low is None else "a number >= 0 (inf allowed)"
                raise ScenarioError(f"plant.wind.{key}", f"expected {want}, got {x!r}")
            if key == "gust_std" and not math.isfinite(x):
                raise ScenarioError("plant.wind.gust_std", f"expected a finite number >= 0, got {x!r}")
            numbers[key] = float(x)
    field = raw.get("gust_field", "per_drone")
    if field not in GUST_FIELDS:
        raise ScenarioError("plant.wind.gust_field", f"expected {' or '.join(GUST_FIELDS)}, got {field!r}")
    with as_scenario_error("plant"):
        return Wind(
            np.array(mean, dtype=float),
            gust_std_mps=numbers.get("gust_std", 0.0),
            gust_time_s=numbers.get("gust_time", 1.0),
            gust_bound_mps=numbers.get("gust_bound"),
            gust_field=field,
        )


def _finite(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
