"""The online loop flown through a recording fake of Crazyswarm2's ``crazyflie_py``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from crazyflie_fake import fake_crazyflie_py

from mpcform.errors import ValidationError
from mpcform.online.crazyswarm import fly_online
from mpcform.online.loop import OnlineLoop
from mpcform.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def test_fly_online_streams_setpoints_and_arrives() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    calls: list[tuple] = []
    swarm = fake_crazyflie_py(calls, 8).Crazyswarm()
    for cf, start in zip(swarm.allcfs.crazyflies, sc.initial_positions_m, strict=True):
        cf.goTo([*start, 1.0], 0.0, 3.0)
    steps = fly_online(loop, swarm, 10.0)
    assert len(steps) == 100
    streamed = [c for c in calls if c[0] == "cmdFullState"]
    assert len(streamed) == 100 * 10 * 8  # every drone, every 10 ms
    assert [c[0] for c in calls[-8:]] == ["notifySetpointsStop"] * 8
    final = np.array([cf.get_position() for cf in swarm.allcfs.crazyflies])
    goal = loop.planner.reference.targets(np.array([10.0]))[0][0]
    np.testing.assert_allclose(final[:, :2], goal, atol=0.02)
    np.testing.assert_allclose(final[:, 2], 1.0)


def test_the_swarm_must_match_the_plan() -> None:
    loop = OnlineLoop.from_scenario(load_scenario(SCENARIOS / "swap_planar_8.toml"))
    with pytest.raises(ValidationError, match="expected 8 Crazyflies"):
        fly_online(loop, fake_crazyflie_py([], 3).Crazyswarm(), 1.0)


@pytest.mark.parametrize(
    ("names", "message"),
    [
        (
            ["cfX"] * 8,
            "names: no Crazyflie named 'cfX' in the swarm (it has cf1, cf2, cf3, cf4, cf5, cf6, cf7, cf8)",
        ),
        (["cf1"] * 6, "names: expected 8 Crazyflie names (one per drone of the plan), got 6"),
        (["cf1"] * 8, "names: expected distinct names, got 'cf1' more than once"),
    ],
)
def test_the_names_are_checked_before_the_first_command(names: list[str], message: str) -> None:
    """A bare KeyError before; a wrong count was found only after the lookups."""
    loop = OnlineLoop.from_scenario(load_scenario(SCENARIOS / "swap_planar_8.toml"))
    calls: list[tuple] = []
    swarm = fake_crazyflie_py(calls, 8).Crazyswarm()
    with pytest.raises(ValidationError) as info:
        fly_online(loop, swarm, 1.0, names)
    assert str(info.value) == message and calls == []
