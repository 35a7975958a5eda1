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


def _far_pair(plant: dict | None) -> dict:
    """Two drones 15.4 m from their goals with a_max = 0.52 m/s^2 well below k v_max = 4.7 m/s^2
    and a 0.45 s horizon (a run of the ordinary-day family)."""
    sc = {
        "version": 1,
        "name": "far_pair",
        "dim": 2,
        "template": {"shape": "explicit", "offsets": [[-0.73, -0.83], [0.73, 0.83]]},
        "limits": {"v_max": 2.4, "d_min": 0.48, "a_max": 0.52},
        "controller": {"kind": "mpc", "gain": 1.96, "horizon": 5, "coupling": "joint"},
        "simulation": {"dt": 0.09, "duration": 20.0},
        "initial": {"positions": [[6.7, 1.25], [8.15, 2.91]]},
        "reference": {"kind": "constant", "centroid": [-7.4, -2.1], "rotation": 0.0, "scale": 1.0},
    }
    return sc | ({"plant": plant} if plant else {})


@pytest.mark.parametrize(
    "plant",
    [
        None,
        {"kind": "lag", "time_constant": 0.3},
        pytest.param({"kind": "quadrotor"}, marks=pytest.mark.slow),
    ],
    ids=["ideal", "lag", "quadrotor"],
)
def test_a_drone_far_from_its_goal_brakes_in_time_instead_of_overshooting(plant: dict | None) -> None:
    """Eq. 14 asks for more speed than the drone can shed at a_max on its way in; the cost's error
    shortened to the braking profile (mpc.plan.braking_error) brings both drones in at 14 s
    (without it they overshot: 22.5 s ideal, 29.8 s quadrotor, never under the lag)."""
    from mpcform.scenario.load import scenario_from_dict

    run = run_scenario(scenario_from_dict(_far_pair(plant)))
    m = run.summary["metrics"]
    assert m["completion"] == 1.0 and m["time_to_complete"] <= 15.0, m["time_to_complete"]
    goal = np.array([[-8.13, -2.93], [-6.67, -1.27]])
    past = np.einsum("tnd,d->tn", run.simulation.positions_m - goal, [14.1, 4.2]) / np.hypot(14.1, 4.2)
    assert past.min() >= -0.1  # never more than 0.1 m beyond the goal along the way in
