"""One planner step's stages (:mod:`mpcform.mpc.pipeline`): under a step budget a late step still
sends its certified command, so a tight budget never holds a swarm, and only a step whose optional
work the wall clock cut (``budget_cut``) can plan differently than without the budget."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _flown(name: str, budget_s: float | None, plant: str | None = None):
    sc = load_scenario(SCENARIOS / name)
    mpc = dataclasses.replace(sc.controller.mpc, coupling="decoupled", solve=None, step_budget_s=budget_s)
    sc = dataclasses.replace(sc, controller=dataclasses.replace(sc.controller, mpc=mpc))
    return run_scenario(sc)


@pytest.mark.parametrize("name", ["swap_planar_8.toml", "swap_spatial_12.toml"])
def test_a_tight_budget_plans_as_none_until_the_wall_clock_cuts(name: str) -> None:
    free, tight = _flown(name, None), _flown(name, 1e-3)
    cuts = [i.budget_cut for i in tight.simulation.infos]
    first = cuts.index(True) if any(cuts) else len(cuts)
    np.testing.assert_array_equal(  # the same commands until a cut (none without split rounds)
        tight.simulation.commands_mps[:first], free.simulation.commands_mps[:first]
    )
    m = tight.summary["metrics"]
    assert m["deadline_misses"] > 0 and m["budget_cuts"] == sum(cuts)  # late steps, still sent
    assert m["completion"] == 1.0 and m["separation_violations"] == 0  # the swarm arrives, safely
    assert not any(i.deadline_missed for i in free.simulation.infos)
