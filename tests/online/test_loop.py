"""The online loop: the planner's own command from measurements, its setpoints, and the deadline."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.online.loop import OnlineLoop, step_time_stats
from mpcform.scenario.build import build_controller
from mpcform.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _fly(loop: OnlineLoop, p: np.ndarray, steps: int) -> list:
    out = []
    for k in range(steps):
        s = loop.step(k * loop.dt_s, p)
        p = p + loop.dt_s * s.command_mps  # the ideal plant
        out.append(s)
    return out


def test_commands_are_the_planners_and_setpoints_start_at_the_measurement() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop, ref = OnlineLoop.from_scenario(sc), build_controller(sc)
    ref.reset(0.0, sc.initial_positions_m)
    p = sc.initial_positions_m.copy()
    for k in range(30):
        s = loop.step(k * sc.simulation.dt_s, p)
        np.testing.assert_array_equal(s.command_mps, ref.step(k * sc.simulation.dt_s, p.copy()).command_mps)
        np.testing.assert_array_equal(s.setpoints.pos_m[0, :, :2], p)
        assert np.all(s.setpoints.pos_m[..., 2] == 1.0) and not s.deadline_missed
        p = p + sc.simulation.dt_s * s.command_mps + 0.01 * np.sin(k + np.arange(16.0)).reshape(8, 2)


def test_a_missed_deadline_sends_the_previous_plans_next_input() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    p = sc.initial_positions_m.copy()
    for s in _fly(loop, p, 12):  # under way
        p = p + loop.dt_s * s.command_mps
    moving, plan = s.command_mps, loop.planner.plan
    assert plan is not None and np.linalg.norm(moving) > 1.0
    planner = loop.planner  # from now on no solve can finish in time
    planner.settings = dataclasses.replace(planner.settings, step_budget_s=1e-9)
    late = loop.step(12 * loop.dt_s, p)
    assert late.deadline_missed and late.info.mode == "fallback" and "deadline" in late.info.status
    np.testing.assert_array_equal(late.command_mps, plan.inputs_mps[1])  # the braking fallback's start
    assert np.all(np.abs(late.command_mps - moving) <= planner.limits.a_max_mps2 * loop.dt_s + 1e-9)
    assert step_time_stats([late])["deadline_miss_share"] == 1.0


def test_decoupled_20_drones_meet_a_100_ms_deadline() -> None:
    sc = load_scenario(SCENARIOS / "swap_spatial_20.toml")
    mpc = dataclasses.replace(sc.controller.mpc, coupling="decoupled", solve=None)
    sc = dataclasses.replace(sc, controller=dataclasses.replace(sc.controller, mpc=mpc))
    loop = OnlineLoop.from_scenario(sc, step_budget_s=sc.simulation.dt_s)
    steps = _fly(loop, sc.initial_positions_m.copy(), 40)
    assert step_time_stats(steps)["deadline_miss_share"] <= 0.01


def test_online_planning_needs_the_mpc() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    tracking = dataclasses.replace(sc, controller=dataclasses.replace(sc.controller, kind="tracking"))
    with pytest.raises(ValidationError, match="controller.kind"):
        OnlineLoop.from_scenario(tracking)
    with pytest.raises(ValidationError, match="setpoint_rate"):
        OnlineLoop.from_scenario(sc, setpoint_rate_hz=15.0)


def test_a_lost_drone_is_commanded_zero_and_a_new_flight_plans_for_every_drone() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    p = sc.initial_positions_m.copy()
    for s in _fly(loop, p, 10):
        p = p + loop.dt_s * s.command_mps
    loop.lose([3], p)
    assert loop.lost_drones.tolist() == [3]
    after = loop.step(10 * loop.dt_s, p)
    assert np.all(after.command_mps[3] == 0.0) and np.linalg.norm(after.command_mps[[2, 4]]) > 0.5
    np.testing.assert_array_equal(after.setpoints.pos_m[:, 3, :2], np.broadcast_to(p[3], (10, 2)))
    with pytest.raises(ValidationError, match="drones"):
        loop.lose([8], p)
    loop.start(0.0, sc.initial_positions_m)
    assert loop.lost_drones.size == 0 and np.linalg.norm(loop.step(0.0, p).command_mps[3]) > 0.0
