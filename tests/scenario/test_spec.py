"""The scenario spec: a frozen scenario with read-only positions, its drone and step counts."""

from __future__ import annotations

import dataclasses

import pytest
from saved_runs import SCENARIOS

from mpcform.scenario.load import load_scenario

WORKED = SCENARIOS / "worked_example.toml"


def test_scenario_is_frozen() -> None:
    s = load_scenario(WORKED)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.name = "other"  # type: ignore[misc]
    with pytest.raises(ValueError):
        s.initial_positions_m[0, 0] = 1.0


@pytest.mark.parametrize(("duration_s", "steps"), [(10.0, 500), (0.05, 2), (0.001, 1)])
def test_drones_and_steps(duration_s: float, steps: int) -> None:
    s = load_scenario(WORKED)
    short = dataclasses.replace(s, simulation=dataclasses.replace(s.simulation, duration_s=duration_s))
    assert short.n == 3 and short.steps == steps
